"""The sensor on a serial line: the MTi driver (hand-shake, output negotiation, streaming, reconnect), bytes
into samples, ports, and the simulated MTi-G on a pseudo-terminal (``device.simulator``)."""
