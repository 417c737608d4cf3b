"""The recording: release detection, the decay pipeline and its sinks (live fit, file, view), the record
daemon, replay, and the guided session (``session``). Its modules are mapped in
docs/architecture.md.
"""
