"""The discrepancy workflow: where a decay model (or a lab's own simulation) and the measurement disagree,
which effect is missing, and the gap shrinking once it is added. Its modules are mapped in
docs/architecture.md; the workflow in docs/diagnose.md.
"""
