"""The run catalogue: one row per decay, session and hull version, in SQLite or PostgreSQL.

``database`` (the URL, the schema, its migrations), ``rows`` (a row from a file), ``writing`` (adding
and updating rows), ``index`` (rows rebuilt from files), ``hooks`` (written as work happens, never in
the way of a file), ``query`` (filters, ``--where``, ``runs()`` as a DataFrame). docs/catalogue.md.
"""
