"""The occupancy-query contract between the map and its users (the planner).

Unknown is not free: every answer says, per point, whether any observation saw it.
`DroanMap` implements `OccupancyMap`; tests and the planner may use any other
implementation with the same shape (synthetic walls, boxes, wires).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True, slots=True)
class OccupancyQuery:
    """Per-point answers of a batched query; all arrays have shape (N,).

    collision: M >= gamma (eq. 4.5).
    occupancy: M = max(sum over nodes of occ(d_s), 0) (eq. 4.5), dimensionless.
    seen: True where at least one observation's field of view contains the point;
        where False the point is unknown (neither free nor occupied).
    solid: collision by located evidence alone (measured depth, a reconstructed catenary,
        true geometry), not by the wire depth prior (4.4.3): that prior puts a wire seen in
        one image anywhere along its rays, so it keeps paths out but cannot say that one given
        point (a goal) is occupied.
    """

    collision: np.ndarray
    occupancy: np.ndarray
    seen: np.ndarray
    solid: np.ndarray


class OccupancyMap(Protocol):
    """Anything that answers batched collision queries for world points."""

    def query(self, points_ned_m: np.ndarray) -> OccupancyQuery:
        """Answers for `(N, 3) float64` world points, local NED frame, m."""
        ...
