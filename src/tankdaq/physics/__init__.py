"""The decay equation: its term vocabulary and named models, integration, a scripted hand-operated decay test
with its simulated sensor, the simplified Ikeda prediction and Froude scaling."""
