"""The live fit: refits while a decay is recorded, on a worker thread, on kernels made ready first."""
