"""tankdaq.viz: the rerun live view (``viz.live``) and PNG report figures (``viz.plots``).

Nothing is imported here: PNG reports should not pay for loading rerun.
"""
