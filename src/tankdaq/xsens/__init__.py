"""The Xsens MT (Xbus) protocol: pure code, no I/O (frames, MTData2 and legacy MTData, configuration
payloads, orientation representations, clock unwrapping, vectorised and streaming decoders).

The live decoder, which every recording, file and port goes through: ``stream_decoder`` (a byte stream fed
in chunks) -> ``column_decoder`` (bytes into columns and samples) -> ``frame_scan`` and ``layouts`` (the
vectorised framing and payload layouts). The reference decoders, which define what that decoder must
give and check it in the tests: ``framer`` (the sequential framer) and ``mtdata2.decode_mtdata2`` (one
message at a time; ``mtdata2`` also holds the data-identifier table and codecs every decoder and the
simulator share). The choices are in docs/protocol.md.
"""
