"""pymavlink in MAVLink 2 mode: the one place the hil harness imports it from."""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil

if mavutil.mavlink.WIRE_PROTOCOL_VERSION != "2.0":
    # mavutil was imported earlier without MAVLINK20: switch its dialect to MAVLink 2
    os.environ["MAVLINK20"] = "1"
    mavutil.set_dialect(mavutil.current_dialect)
mavlink = mavutil.mavlink

__all__ = ["mavlink", "mavutil"]
