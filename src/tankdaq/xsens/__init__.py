"""The Xsens MT (Xbus) protocol: pure code, no I/O (frames, MTData2 and legacy MTData, configuration
payloads, orientation representations, clock unwrapping, vectorised and streaming decoders). Its modules are
mapped in docs/architecture.md; the choices made in docs/protocol.md.
"""
