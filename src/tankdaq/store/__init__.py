"""tankdaq.store: one MCAP file per decay (writer, reader, recovery, names) and CSV import.

The public entry points live in their modules: ``store.writer.RecordingWriter``,
``store.reader.read_recording`` / ``read_decay_runs`` / ``iter_raw_chunks``,
``store.recover.recover``, ``store.naming`` and ``store.csv_import``. Nothing is
imported here, so reading a CSV does not load the MCAP stack.
"""
