"""PX4 SITL's live ground truth (`hil.px4_truth.Px4TruthTap`) and the flat earth it uses."""

from __future__ import annotations

import time

import numpy as np
import pytest
from pymavlink import mavutil

from companion.cli.sim_flight import free_udp_port
from geometry.geodetic import lat_lon_deg, north_east_m
from hil.px4_truth import Px4TruthTap, sih_truth_port

LAT0, LON0 = 47.397743, 8.545594  # PX4 SITL's home


def test_the_truth_port_follows_the_instance_of_the_offboard_port() -> None:
    assert sih_truth_port("udpin://0.0.0.0:14540") == 19410
    assert sih_truth_port("udpin://0.0.0.0:14547") == 19417
    assert sih_truth_port("udpin://0.0.0.0:14600") is None  # not a PX4 SITL instance
    assert sih_truth_port("serial:///dev/ttyACM0:921600") is None


def test_flat_earth_round_trips_and_has_the_wgs84_scale() -> None:
    lat, lon = lat_lon_deg(120.0, -75.0, LAT0, LON0)
    assert north_east_m(lat, lon, LAT0, LON0) == pytest.approx((120.0, -75.0), abs=1e-6)
    north, east = north_east_m(LAT0 + 0.001, LON0 + 0.001, LAT0, LON0)
    assert north == pytest.approx(111.2, abs=0.1) and east == pytest.approx(75.4, abs=0.1)


def test_the_tap_reads_sih_truth_relative_to_its_first_sample() -> None:
    port = free_udp_port()
    tap = Px4TruthTap(port)
    sender = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1)

    def send(north_m: float, east_m: float, up_m: float, vn_mps: float) -> None:
        lat, lon = lat_lon_deg(north_m, east_m, LAT0, LON0)
        q = [np.cos(0.25), 0.0, 0.0, np.sin(0.25)]  # yaw 0.5 rad
        sender.mav.hil_state_quaternion_send(
            0, q, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), round((488.0 + up_m) * 1e3),
            round(vn_mps * 100), 0, 0, 0, 0, 0, 0, 0,
        )  # fmt: skip

    try:
        assert tap.state() is None
        send(0.0, 0.0, 0.0, 0.0)  # on the ground where it booted: the origin
        assert tap.wait(2.0)
        send(10.0, -4.0, 3.0, 2.0)
        deadline = time.monotonic() + 2.0
        while tap.state()[1][0] < 5.0 and time.monotonic() < deadline:
            time.sleep(0.01)
        quaternion, position = tap.state()
        assert position == pytest.approx([10.0, -4.0, -3.0], abs=0.25)  # + <= 0.1 s at 2 m/s
        assert position[0] >= 10.0 - 0.01  # carried forward along the true velocity
        assert quaternion == pytest.approx([np.cos(0.25), 0.0, 0.0, np.sin(0.25)], abs=1e-6)
    finally:
        tap.close()
        sender.close()


def test_a_tap_without_a_simulator_says_so() -> None:
    tap = Px4TruthTap(free_udp_port())
    try:
        assert not tap.wait(0.3) and tap.state() is None
    finally:
        tap.close()
