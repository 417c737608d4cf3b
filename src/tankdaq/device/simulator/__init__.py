"""The simulated MTi-G, in parts (as gpsfake separates its log source, its fake pty and its session):

- ``sources``: where the data comes from (``ScriptedSource``: a scripted decay scenario;
  ``RecordedSource``: the raw bytes of a recording or capture, re-sent at their recorded pace);
- ``firmware``: the MT messages and the device states (``Firmware``, ``Behaviour``); ``identity``: who it
  says it is (``DeviceIdentity``);
- ``output``: the output configuration in force and the encoding of samples into messages;
- ``pty_link``: the pseudo-terminal the driver opens, its stable and by-id links, the baud rate;
- ``faults``: line noise, stalls, unplugs;
- ``mti``: ``SimulatedMTi``, which runs them together (the one entry point to start and stop).
"""

from .faults import Faults
from .firmware import Behaviour, ReceivedMessage, refused_orientation
from .identity import DeviceIdentity
from .mti import SimulatedMTi
from .output import default_configuration, effective_configuration
from .pty_link import OWNER_FILE, TEMP_PREFIX, sweep_stale_folders
from .sources import RecordedSource, ScriptedSource

__all__ = [
    "OWNER_FILE",
    "TEMP_PREFIX",
    "Behaviour",
    "DeviceIdentity",
    "Faults",
    "ReceivedMessage",
    "RecordedSource",
    "ScriptedSource",
    "SimulatedMTi",
    "default_configuration",
    "effective_configuration",
    "refused_orientation",
    "sweep_stale_folders",
]
