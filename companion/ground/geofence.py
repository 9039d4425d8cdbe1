"""The geofence (pure): is a goal, and the straight leg to it, inside the fence and the altitude
band?

Frames: horizontal positions are local NED (north, east) from the autopilot's origin, m; the
altitude band is above home, m (`-(down - home_down)`). Boundaries count as outside.
Geographic goals (WGS84 lat/lon) are turned into local NED with the home position on a flat
earth (`geometry.geodetic`: the tangent plane at home). Altitudes are above home, along the
local vertical.

Every check answers with a reason a person can act on ("" when the goal is fine) and names
the setting that drew the line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.ground.params import FenceShape, GeofenceParams
from companion.ground.polygon import inside_polygon, segment_inside_polygon
from companion.ground.protocol import (
    Command,
    GeoTarget,
    GotoCommand,
    MissionCommand,
    NedTarget,
    TakeoffCommand,
)
from geometry.geodetic import north_east_m


@dataclass(frozen=True, slots=True)
class HomePosition:
    """Home: WGS84 latitude/longitude (deg) and its position in local NED (3,), m."""

    lat_deg: float
    lon_deg: float
    position_ned_m: np.ndarray


def geo_to_ned_m(target: GeoTarget, home: HomePosition) -> np.ndarray:
    """(3,) float64 local NED of a geographic goal, m.

    Flat earth at home (`geometry.geodetic.north_east_m`); down = home_down - altitude above
    home.
    """
    north_m, east_m = north_east_m(target.lat_deg, target.lon_deg, home.lat_deg, home.lon_deg)
    home_ned = np.asarray(home.position_ned_m, dtype=np.float64)
    return np.array([home_ned[0] + north_m, home_ned[1] + east_m, home_ned[2] - target.altitude_m])


def target_ned_m(target: NedTarget | GeoTarget, home: HomePosition | None) -> np.ndarray | str:
    """(3,) local NED of a goal, m, or why it cannot be placed (a geographic goal before the
    home position is known)."""
    if isinstance(target, NedTarget):
        return target.ned_m
    if home is None:
        return "home position not known yet: wait for it, or send a local NED goal"
    return geo_to_ned_m(target, home)


class Geofence:
    """The configured fence (`GeofenceParams`): a cylinder or a polygon and an altitude band."""

    def __init__(self, params: GeofenceParams) -> None:
        self.params = params
        self._polygon = [tuple(map(float, v)) for v in params.polygon_ned_m]

    def horizontal_violation(self, point_ned_m: np.ndarray) -> str:
        """Why the (north, east) of `point_ned_m` is outside the outline ("" inside)."""
        p = self.params
        north_m, east_m = float(point_ned_m[0]), float(point_ned_m[1])
        if p.shape is FenceShape.CYLINDER:
            distance_m = math.hypot(north_m - p.center_ned_m[0], east_m - p.center_ned_m[1])
            if distance_m < p.radius_m:
                return ""
            return (
                f"({north_m:.1f}, {east_m:.1f}) m is {distance_m:.1f} m from the fence centre "
                f"({p.center_ned_m[0]:.1f}, {p.center_ned_m[1]:.1f}): outside its radius of "
                f"{p.radius_m:.1f} m (geofence.radius_m)"
            )
        if inside_polygon((north_m, east_m), self._polygon):
            return ""
        return (
            f"({north_m:.1f}, {east_m:.1f}) m is outside the fence polygon (geofence.polygon_ned_m)"
        )

    def altitude_violation(self, point_ned_m: np.ndarray, home_ned_m: np.ndarray) -> str:
        """Why the altitude of `point_ned_m` above home is outside the band ("" inside)."""
        p = self.params
        altitude_m = -(float(point_ned_m[2]) - float(home_ned_m[2]))
        if altitude_m > p.max_altitude_m:
            return (
                f"altitude {altitude_m:.1f} m above home is over the fence ceiling of "
                f"{p.max_altitude_m:.1f} m (geofence.max_altitude_m)"
            )
        if altitude_m < p.min_altitude_m:
            return (
                f"altitude {altitude_m:.1f} m above home is under the fence floor of "
                f"{p.min_altitude_m:.1f} m (geofence.min_altitude_m)"
            )
        return ""

    def point_violation(self, point_ned_m: np.ndarray, home_ned_m: np.ndarray) -> str:
        """Why the point is outside the fence or the altitude band ("" inside both)."""
        return self.horizontal_violation(point_ned_m) or self.altitude_violation(
            point_ned_m, home_ned_m
        )

    def leg_violation(
        self, start_ned_m: np.ndarray | None, end_ned_m: np.ndarray, home_ned_m: np.ndarray
    ) -> str:
        """Why the straight leg from `start_ned_m` to the goal `end_ned_m` is refused ("" fine).

        The goal must be inside the fence and the band. From a start inside the outline the
        whole leg must stay inside it (a cylinder and the band are convex, so their ends
        decide; a polygon's edges must not be touched). From a start outside (after a breach)
        or unknown (None), only the goal is checked: flying back in is the operator's call.
        """
        problem = self.point_violation(end_ned_m, home_ned_m)
        if problem or start_ned_m is None or self.params.shape is FenceShape.CYLINDER:
            return problem
        start = (float(start_ned_m[0]), float(start_ned_m[1]))
        end = (float(end_ned_m[0]), float(end_ned_m[1]))
        if inside_polygon(start, self._polygon) and not segment_inside_polygon(
            start, end, self._polygon
        ):
            return (
                f"the straight leg from ({start[0]:.1f}, {start[1]:.1f}) to ({end[0]:.1f}, "
                f"{end[1]:.1f}) m leaves the fence polygon (geofence.polygon_ned_m): add a "
                "waypoint inside"
            )
        return ""

    def command_violation(
        self,
        command: Command,
        position_ned_m: np.ndarray | None,
        home: HomePosition | None,
        home_ned_m: np.ndarray | None = None,
    ) -> str:
        """Why `command` would take the vehicle outside the fence ("" when it would not).

        takeoff: its altitude must be inside the band and the vehicle inside the outline;
        goto and mission: every goal and every leg, from `position_ned_m` (local NED, m, None
        when unknown) through the waypoints in order. Altitudes are above `home_ned_m` (the
        home's NED when `home` is given, else the local origin). Other commands do not move
        the vehicle anywhere new.
        """
        if home_ned_m is None:
            home_ned_m = np.zeros(3) if home is None else np.asarray(home.position_ned_m)
        if isinstance(command, TakeoffCommand):
            climb_to = np.array([0.0, 0.0, float(home_ned_m[2]) - command.altitude_m])
            problem = self.altitude_violation(climb_to, home_ned_m)
            if not problem and position_ned_m is not None:
                problem = self.horizontal_violation(position_ned_m)
            return f"takeoff: {problem}" if problem else ""
        if isinstance(command, GotoCommand):
            waypoints = [command]
        elif isinstance(command, MissionCommand):
            waypoints = list(command.waypoints)
        else:
            return ""
        start = position_ned_m
        for index, waypoint in enumerate(waypoints):
            goal = target_ned_m(waypoint.target, home)
            where = "goal" if isinstance(command, GotoCommand) else f"waypoint {index}"
            if isinstance(goal, str):
                return f"{where}: {goal}"
            problem = self.leg_violation(start, goal, home_ned_m)
            if problem:
                return f"{where}: {problem}"
            start = goal
        return ""
