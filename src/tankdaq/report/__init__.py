"""``tankdaq report``: one self-contained HTML file and a PDF a lab hands over (docs/report.md).

Data flows one way: the inputs are found (``report.sources``), fitted by ``tankdaq.identify``, turned
into typed tables and figures (``report.content``, ``report.tables``, ``report.provenance``), and only
then rendered (``report.html``, ``report.pdf``); ``--json`` prints the same content, so the three hold
the same numbers. ``report.make`` is the API call (``tankdaq.make_report``).
"""
