"""The discrepancy workflow: where a decay model and the measurement disagree, and which effect is missing.

``workflow.Diagnoser`` fits a baseline, reads its residual (``residuals``), refits
candidates from the effect library (``effects``) with its own fast output-error
engine (``fitting``), and tells the story (``report``); ``synthetic`` makes
known-truth decays with hidden effects to prove it. ``compare.SimulationComparison``
does the same against a lab's own simulation (``simulation``: a time series, a
hull's model, a prediction), with the correction in SI (``correction``) and its
story (``sim_report``). See docs/diagnose.md.
"""
