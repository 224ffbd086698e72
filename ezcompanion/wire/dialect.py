"""pymavlink as this project speaks it: ArduPilot's ``ardupilotmega`` dialect, MAVLink 2.

pymavlink chooses its wire version from the ``MAVLINK20`` variable when it is first loaded,
so this module sets it before the import; every other module of the package gets pymavlink
from here.
"""

from __future__ import annotations

import os
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")

from pymavlink import mavutil

if mavutil.mavlink.WIRE_PROTOCOL_VERSION != "2.0" or mavutil.current_dialect != "ardupilotmega":
    os.environ["MAVLINK20"] = "1"
    mavutil.set_dialect("ardupilotmega")

__all__ = ["Address", "Message", "mavlink", "mavutil"]

#: The generated dialect module: message classes and every MAVLink enum value as a constant.
mavlink: Any = mavutil.mavlink

#: A decoded MAVLink message (a pymavlink message object; fields are attributes).
Message = Any

#: A transport address: ``(host, port)`` of a UDP peer; None where the link has one peer
#: only (TCP, serial).
Address = tuple[str, int] | None
