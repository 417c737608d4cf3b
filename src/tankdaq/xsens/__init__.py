"""The Xsens MT (Xbus) protocol: pure code, no I/O.

``constants`` (message ids, error and baud codes), ``frame`` / ``framer`` (one frame, a byte
stream), ``mtdata2`` (the data-identifier table and codec), ``control`` (configuration
payloads), ``legacy`` (Mark III MTData), ``timebase`` (SampleTimeFine unwrapping, counter
gaps), ``batch`` / ``stream`` (vectorised decoding into columns and samples). Choices are
recorded in docs/protocol.md.
"""
