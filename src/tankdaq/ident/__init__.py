"""Identification of the decay equation's coefficients from free-decay runs: the estimators (output error
is the answer; equation error; the papers' GA and PSO), honest intervals, plausibility, the model chosen by
the data, derived results, live refits and campaigns. Its modules are mapped in docs/architecture.md; the
models and checks in docs/models.md.
"""
