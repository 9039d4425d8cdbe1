"""The true path of a PX4 SITL flight, live or from its flight log, for `sim --connect`.

Live: `Px4TruthTap` reads the ground truth PX4 SITL streams from its SIH simulator, so the
cameras render from where the vehicle truly is (as real cameras see) while the stack flies on
PX4's drifting estimate, and the judge samples the same truth.

From the log: PX4's SIH simulator logs its ground truth (`vehicle_local_position_groundtruth`,
NED from where it booted, m) beside the estimate, and the land detector's state
(`vehicle_land_detected`): the flight is judged on the first, and touching the ground counts
as no collision while the land detector says the vehicle is landed or touching down (ground
contact, maybe landed), and while it climbs out of its take-off or descends into its landing
(below `_AIRBORNE_M` before it first rose above it, or after it last was). Needs `pyulog`.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np

from geometry.geodetic import north_east_m

_GROUND_FLAGS = ("landed", "maybe_landed", "ground_contact")
_AIRBORNE_M = 1.0  # height above the start that ends the take-off and begins the landing


def newest_ulog(path: str | Path) -> Path:
    """`path` itself when it is a `.ulg` file, else the newest `.ulg` below the folder."""
    path = Path(path)
    if path.is_file():
        return path
    logs = sorted(path.rglob("*.ulg"), key=lambda p: p.stat().st_mtime)
    if not logs:
        raise FileNotFoundError(f"no PX4 flight log (.ulg) below {path}")
    return logs[-1]


def ulog_truth(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times (N,) s since PX4 booted, true positions (N, 3) NED m, on_ground (N,) bool) of
    the newest flight log at `path`."""
    from pyulog import ULog

    log = ULog(
        str(newest_ulog(path)), ["vehicle_local_position_groundtruth", "vehicle_land_detected"]
    )
    topics = {d.name: d.data for d in log.data_list}
    if "vehicle_local_position_groundtruth" not in topics:
        raise ValueError("the flight log holds no ground truth (not a SIH simulation?)")
    truth = topics["vehicle_local_position_groundtruth"]
    times_s = truth["timestamp"] / 1e6
    positions = np.stack([truth["x"], truth["y"], truth["z"]], axis=1).astype(np.float64)
    on_ground = np.zeros(len(times_s), bool)
    land = topics.get("vehicle_land_detected")
    if land is not None:
        flags = np.zeros(len(land["timestamp"]), bool)
        for name in _GROUND_FLAGS:
            flags |= land[name].astype(bool)
        index = np.searchsorted(land["timestamp"], truth["timestamp"], side="right") - 1
        on_ground = np.where(index >= 0, flags[np.clip(index, 0, None)], True)
    high = np.flatnonzero(-positions[:, 2] > _AIRBORNE_M)
    if high.size:
        on_ground[: high[0]] = True
        on_ground[high[-1] + 1 :] = True
    return times_s, positions, on_ground


SIH_TRUTH_PORT_BASE = 19410  # PX4 SITL streams SIH's truth to UDP 19410 + instance
OFFBOARD_PORT_BASE = 14540  # ... and its offboard (API) link to 14540 + instance
_MAX_CARRY_S = 0.1  # the newest sample is carried forward at its velocity at most this long


def sih_truth_port(connect_url: str) -> int | None:
    """The UDP port PX4 SITL streams SIH's ground truth to for the instance whose offboard
    link `connect_url` (udpin://HOST:14540+i) listens on, or None for another URL."""
    port = connect_url.rsplit(":", 1)[-1]
    if not port.isdigit() or not 0 <= int(port) - OFFBOARD_PORT_BASE <= 9:
        return None
    return SIH_TRUTH_PORT_BASE + int(port) - OFFBOARD_PORT_BASE


class Px4TruthTap:
    """PX4 SITL's live ground truth: the HIL_STATE_QUATERNION its SIH simulator streams
    (25 Hz, to UDP `sih_truth_port`; px4-rc.mavlink) for a viewer, read on a daemon thread.

    Positions are NED from the first sample (the vehicle on the ground where it booted, the
    origin of PX4's logged truth), m, on a flat earth (`geometry.geodetic`).
    """

    def __init__(self, port: int) -> None:
        from pymavlink import mavutil

        self._connection = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
        self._latest: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._origin: tuple[float, float, float] | None = None  # lat, lon deg, alt m
        self._arrived = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="px4_truth", daemon=True)
        self._thread.start()

    def wait(self, timeout_s: float) -> bool:
        """True once a sample arrived (within `timeout_s`)."""
        return self._arrived.wait(timeout_s)

    def state(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(attitude quaternion wxyz, position NED m) of the body now: the newest sample
        carried forward at its velocity (at most `_MAX_CARRY_S`); None before the first."""
        latest = self._latest
        if latest is None:
            return None
        stamp_s, quaternion, position, velocity = latest
        age_s = float(np.clip(time.monotonic() - stamp_s, 0.0, _MAX_CARRY_S))
        return quaternion, position + velocity * age_s

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._connection.close()

    def _read(self) -> None:
        while not self._stop.is_set():
            message = self._connection.recv_match(
                type="HIL_STATE_QUATERNION", blocking=True, timeout=0.2
            )
            if message is None:
                continue
            lat_deg, lon_deg, alt_m = message.lat * 1e-7, message.lon * 1e-7, message.alt * 1e-3
            if self._origin is None:
                self._origin = (lat_deg, lon_deg, alt_m)
            lat0_deg, lon0_deg, alt0_m = self._origin
            north_m, east_m = north_east_m(lat_deg, lon_deg, lat0_deg, lon0_deg)
            position = np.array([north_m, east_m, alt0_m - alt_m])
            velocity = np.array([message.vx, message.vy, message.vz], dtype=np.float64) * 0.01
            quaternion = np.asarray(message.attitude_quaternion, dtype=np.float64)
            self._latest = (time.monotonic(), quaternion, position, velocity)
            self._arrived.set()
