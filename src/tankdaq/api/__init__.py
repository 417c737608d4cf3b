"""The public Python API (``tankdaq.read``, ``identify``, ``campaign``, ``diagnose``, ``simulate``,
``compare_models``): the library's pipelines for notebooks and scripts, with pandas DataFrames in named
units at this edge.

``tankdaq/__init__.py`` exports these names lazily (``import tankdaq`` stays cheap); the command line
calls the same functions (``tankdaq identify`` is ``identify``, ``tankdaq campaign`` is ``campaign``,
``tankdaq diagnose`` is ``diagnose``, ``tankdaq identify --compare`` is ``compare_models``), and so does
the guided session's report (``campaign``). Whatever ``tankdaq.__all__`` does not name is internal.
docs/api.md has the examples.
"""
