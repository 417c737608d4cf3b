"""tankdaq.viz: the rerun live view (``viz.live``, its feed thread ``viz.view_feed``, the viewer process
``viz.viewer``) and PNG report figures (``viz.plots``).

Nothing is imported here: PNG reports should not pay for loading rerun. rerun's own Rust log
lines ("Flush timed out", "File-writer thread shut down") are silenced unless ``RUST_LOG`` is set:
the live view reports viewer trouble in one line of its own. This must run before rerun is
imported, which is why it sits in the package's ``__init__``.
"""

import os

os.environ.setdefault("RUST_LOG", "off")
