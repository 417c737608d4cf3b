"""tankdaq: towing-tank decay-test acquisition with live identification.

Data flows one way: serial bytes -> frames (xsens) -> samples -> decays (acquire)
-> fits (ident) -> views and files (viz, store). Every stage is usable from Python.
"""

__version__ = "0.1.0"
