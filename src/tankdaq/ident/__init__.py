"""Identification of the decay equation's coefficients from free-decay runs.

``models`` (term sets, seed aliases), ``kernels`` (compiled RK4 with exact
sensitivities), ``equation_error`` / ``output_error`` (the estimators; output
error is the answer), ``estimators`` (the method registry), ``uncertainty``
(HAC, block bootstrap, repeats, warnings), ``derived`` (period, B_eq, Bertin N,
dimensional), ``online`` (live refits), ``report`` (JSON, text, model
comparison). See docs/models.md.
"""
