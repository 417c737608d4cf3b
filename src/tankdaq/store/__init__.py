"""tankdaq.store: one MCAP file per decay (writer, reader, recovery, names), CSV import, and the one way in.

The public entry points live in their modules: ``store.writer.RecordingWriter``,
``store.reader.read_recording`` / ``read_decay_runs`` / ``iter_raw_chunks``,
``store.recover.recover`` (from ``store.record_scan.RecordScan``), ``store.naming`` (the name
grammar, written and read),
``store.csv_import`` and ``store.inputs`` (``read_runs``: the reader by suffix). Nothing
is imported here, so reading a CSV does not load the MCAP stack. The store only reads
and writes: it never imports ``ident``.
"""
