"""AUV diving-plane manoeuvres (seed 003): the vehicle model, LS-SVM identification of its derivatives, the
sensitivity analysis and validation by re-simulation. docs/auv.md."""
