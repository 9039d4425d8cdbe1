"""The geofence (pure): goals, legs, the altitude band, geographic goals, and the outline's
own validation."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pydantic import ValidationError

from companion.ground.geofence import Geofence, HomePosition, geo_to_ned_m, target_ned_m
from companion.ground.params import GeofenceParams
from companion.ground.polygon import inside_polygon, segment_inside_polygon, segments_touch
from companion.ground.protocol import GeoTarget, NedTarget, parse_command

HOME = np.zeros(3)
# a U-shaped (concave) fence: the notch 10 < north < 30, -10 < east < 10 is outside
U_SHAPE = [(0.0, -30.0), (40.0, -30.0), (40.0, 30.0), (0.0, 30.0), (0.0, 10.0), (30.0, 10.0)]
U_SHAPE += [(30.0, -10.0), (0.0, -10.0)]


def cylinder(**fields: object) -> Geofence:
    return Geofence(GeofenceParams(**fields))


def test_cylinder_and_altitude_band() -> None:
    fence = cylinder(center_ned_m=(10.0, 0.0), radius_m=20.0, min_altitude_m=1.0)
    assert fence.point_violation(np.array([25.0, 0.0, -5.0]), HOME) == ""
    outside = fence.point_violation(np.array([31.0, 0.0, -5.0]), HOME)
    assert outside.startswith("(31.0, 0.0) m is 21.0 m from the fence centre (10.0, 0.0)")
    assert outside.endswith("outside its radius of 20.0 m (geofence.radius_m)")
    assert fence.point_violation(np.array([30.0, 0.0, -5.0]), HOME) != ""  # the edge is out
    ceiling = fence.point_violation(np.array([0.0, 0.0, -50.5]), HOME)
    assert "altitude 50.5 m above home is over the fence ceiling of 50.0 m" in ceiling
    floor = fence.point_violation(np.array([0.0, 0.0, -0.5]), HOME)
    assert "under the fence floor of 1.0 m (geofence.min_altitude_m)" in floor
    # altitudes are above home, not above the local origin
    raised_home = np.array([0.0, 0.0, -10.0])
    assert fence.point_violation(np.array([0.0, 0.0, -10.5]), raised_home) != ""
    assert fence.point_violation(np.array([0.0, 0.0, -15.0]), raised_home) == ""


def test_polygon_goals_and_legs_around_a_notch() -> None:
    fence = Geofence(GeofenceParams(shape="polygon", polygon_ned_m=U_SHAPE))
    left, right = np.array([20.0, -20.0, -5.0]), np.array([20.0, 20.0, -5.0])
    assert fence.point_violation(left, HOME) == "" and fence.point_violation(right, HOME) == ""
    notch = fence.point_violation(np.array([20.0, 0.0, -5.0]), HOME)
    assert "outside the fence polygon (geofence.polygon_ned_m)" in notch
    # straight across the notch: both ends inside, the leg leaves the fence
    across = fence.leg_violation(left, right, HOME)
    assert "leaves the fence polygon" in across and "add a waypoint inside" in across
    # around the notch through the top of the U
    top = np.array([35.0, -20.0, -5.0])
    assert fence.leg_violation(left, top, HOME) == ""
    assert fence.leg_violation(top, np.array([35.0, 20.0, -5.0]), HOME) == ""
    # after a breach (start outside), flying back in is allowed
    assert fence.leg_violation(np.array([50.0, 0.0, -5.0]), top, HOME) == ""


def test_commands_are_checked_goal_by_goal_and_leg_by_leg() -> None:
    fence = Geofence(GeofenceParams(shape="polygon", polygon_ned_m=U_SHAPE, max_altitude_m=20.0))
    here = np.array([5.0, -20.0, -2.0])

    def check(payload: dict) -> str:
        command = parse_command(json.dumps({"v": 1, "id": "c", **payload}).encode())
        assert not isinstance(command, str) and hasattr(command, "type"), command
        return fence.command_violation(command, here, None)

    def wp(n: float, e: float, d: float = -5.0) -> dict:
        return {"target": {"north_m": n, "east_m": e, "down_m": d}}

    assert check({"type": "goto", **wp(35, 20)}).startswith("goal: the straight leg from")
    assert check({"type": "goto", **wp(35, -20)}) == ""
    ok = [wp(35, -20), wp(35, 20), wp(5, 20)]
    assert check({"type": "mission", "waypoints": ok}) == ""
    bad = [wp(35, -20), wp(35, 20), wp(5, 20, -25)]
    assert check({"type": "mission", "waypoints": bad}).startswith(
        "waypoint 2: altitude 25.0 m above home is over the fence ceiling"
    )
    assert check({"type": "takeoff", "altitude_m": 25}).startswith("takeoff: altitude 25.0 m")
    assert check({"type": "takeoff", "altitude_m": 3}) == ""
    assert check({"type": "land"}) == "" and check({"type": "set_speed", "speed_mps": 3}) == ""
    geo = {"type": "goto", "target": {"lat_deg": 47.0, "lon_deg": 8.0, "altitude_m": 5.0}}
    assert check(geo) == "goal: home position not known yet: wait for it, or send a local NED goal"


def test_geographic_goals_on_a_flat_earth_at_home() -> None:
    home = HomePosition(47.0, 8.0, np.array([2.0, -1.0, -0.5]))
    # the WGS84 length of a degree at latitude phi, by its usual series:
    # latitude 111132.92 - 559.82 cos 2phi + 1.175 cos 4phi (111,170.8 m at 47 deg),
    # longitude 111412.84 cos phi - 93.5 cos 3phi + 0.118 cos 5phi (76,055.2 m)
    phi = math.radians(47.0)
    lat_deg_m = 111132.92 - 559.82 * math.cos(2 * phi) + 1.175 * math.cos(4 * phi)
    lon_deg_m = 111412.84 * math.cos(phi) - 93.5 * math.cos(3 * phi) + 0.118 * math.cos(5 * phi)
    north = geo_to_ned_m(GeoTarget(lat_deg=47.001, lon_deg=8.0, altitude_m=10.0), home)
    np.testing.assert_allclose(north, [2.0 + lat_deg_m / 1000, -1.0, -10.5], atol=0.001)
    east = geo_to_ned_m(GeoTarget(lat_deg=47.0, lon_deg=8.001, altitude_m=0.0), home)
    np.testing.assert_allclose(east, [2.0, -1.0 + lon_deg_m / 1000, -0.5], atol=0.001)
    # across the antimeridian the short way round
    date_line = HomePosition(0.0, 179.9995, np.zeros(3))
    west = geo_to_ned_m(GeoTarget(lat_deg=0.0, lon_deg=-179.9995, altitude_m=0.0), date_line)
    assert west[1] == pytest.approx(111.32, abs=0.01)
    # against the exact tangent plane (WGS84 -> ECEF -> local NED): under 1 cm at 300 m
    # and 10 cm at 1 km from home, whatever the bearing
    for distance_m, tolerance_m in ((300.0, 0.01), (1000.0, 0.1)):
        for bearing in np.linspace(0.0, 2 * math.pi, 12, endpoint=False):
            lat = 47.0 + distance_m * math.cos(bearing) / lat_deg_m
            lon = 8.0 + distance_m * math.sin(bearing) / lon_deg_m
            exact = _tangent_plane_ned_m(47.0, 8.0, lat, lon)
            ours = geo_to_ned_m(GeoTarget(lat_deg=lat, lon_deg=lon, altitude_m=0.0), home)
            assert np.hypot(*(ours[:2] - home.position_ned_m[:2] - exact[:2])) < tolerance_m
    ned = NedTarget(north_m=1.0, east_m=2.0, down_m=-3.0)
    np.testing.assert_array_equal(target_ned_m(ned, None), [1.0, 2.0, -3.0])


def _tangent_plane_ned_m(lat0_deg: float, lon0_deg: float, lat_deg: float, lon_deg: float):
    """(north, east) of a point on the WGS84 ellipsoid in the exact tangent plane at lat0/lon0."""
    a_m, e2 = 6378137.0, 6.69437999014e-3

    def ecef(lat: float, lon: float) -> np.ndarray:
        p, q = math.radians(lat), math.radians(lon)
        n = a_m / math.sqrt(1 - e2 * math.sin(p) ** 2)
        return np.array(
            [
                n * math.cos(p) * math.cos(q),
                n * math.cos(p) * math.sin(q),
                n * (1 - e2) * math.sin(p),
            ]
        )

    p, q = math.radians(lat0_deg), math.radians(lon0_deg)
    d = ecef(lat_deg, lon_deg) - ecef(lat0_deg, lon0_deg)
    north = (
        -math.sin(p) * math.cos(q) * d[0] - math.sin(p) * math.sin(q) * d[1] + math.cos(p) * d[2]
    )
    east = -math.sin(q) * d[0] + math.cos(q) * d[1]
    return np.array([north, east])


def test_fence_outline_is_validated() -> None:
    for vertices, message in [
        ([(0, 0), (1, 0)], "at least 3 vertices"),
        ([(0, 0), (1, 0), (2, 0)], "no area"),
        ([(0, 0), (10, 10), (10, 0), (0, 12)], "must not intersect itself"),
        ([(0, 0), (10, 0), (10, 10), (0, 10), (5, 10), (5, -5)], "must not intersect itself"),
    ]:
        with pytest.raises(ValidationError, match=message):
            GeofenceParams(shape="polygon", polygon_ned_m=vertices)
    with pytest.raises(ValidationError, match="finite"):
        GeofenceParams(center_ned_m=(math.nan, 0.0))
    with pytest.raises(ValidationError, match="max_altitude_m must be above"):
        GeofenceParams(min_altitude_m=10.0, max_altitude_m=5.0)
    GeofenceParams(shape="polygon", polygon_ned_m=U_SHAPE)  # concave is fine


def test_plane_geometry() -> None:
    square = [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)]
    assert inside_polygon((5.0, 5.0), square) and not inside_polygon((10.0, 5.0), square)
    assert not inside_polygon((11.0, 5.0), square) and not inside_polygon((0.0, 0.0), square)
    assert segments_touch((0, 0), (2, 2), (0, 2), (2, 0))  # crossing
    assert segments_touch((0, 0), (2, 0), (2, 0), (3, 1))  # sharing an end
    assert segments_touch((0, 0), (4, 0), (1, 0), (2, 0))  # overlapping
    assert not segments_touch((0, 0), (1, 0), (2, 0), (3, 0))  # collinear, apart
    assert not segments_touch((0, 0), (1, 1), (0, 1), (0.4, 0.6))
    assert segment_inside_polygon((1.0, 1.0), (9.0, 9.0), square)
    assert not segment_inside_polygon((1.0, 1.0), (10.0, 10.0), square)
