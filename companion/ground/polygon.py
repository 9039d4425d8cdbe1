"""Plane geometry of the geofence outline (pure): segments, simple polygons, containment.

Points are (north, east) tuples in local NED, m. Boundaries count as outside, so every
answer errs on the safe side.
"""

from __future__ import annotations

Point2 = tuple[float, float]


def _orientation(a: Point2, b: Point2, c: Point2) -> float:
    """Twice the signed area of the triangle a, b, c (> 0: counter-clockwise in (n, e))."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _within_box(p: Point2, q: Point2, r: Point2) -> bool:
    """Whether r lies in the bounding box of the segment pq."""
    return min(p[0], q[0]) <= r[0] <= max(p[0], q[0]) and min(p[1], q[1]) <= r[1] <= max(p[1], q[1])


def segments_touch(a: Point2, b: Point2, c: Point2, d: Point2) -> bool:
    """Whether the closed segments ab and cd share a point (crossing or touching)."""
    d1, d2 = _orientation(c, d, a), _orientation(c, d, b)
    d3, d4 = _orientation(a, b, c), _orientation(a, b, d)
    if ((d1 > 0 > d2) or (d1 < 0 < d2)) and ((d3 > 0 > d4) or (d3 < 0 < d4)):
        return True
    return (
        (d1 == 0 and _within_box(c, d, a))
        or (d2 == 0 and _within_box(c, d, b))
        or (d3 == 0 and _within_box(a, b, c))
        or (d4 == 0 and _within_box(a, b, d))
    )


def edges(vertices: list[Point2]) -> list[tuple[Point2, Point2]]:
    """The closed polygon's edges, vertex i to vertex i + 1 (the last back to the first)."""
    n = len(vertices)
    return [(vertices[i], vertices[(i + 1) % n]) for i in range(n)]


def polygon_problem(vertices: list[Point2]) -> str:
    """Why `vertices` is not a simple polygon with an area; empty when it is one."""
    n = len(vertices)
    if n < 3:
        return f"a polygon needs at least 3 vertices, got {n}"
    outline = edges(vertices)
    if abs(sum(_orientation((0.0, 0.0), a, b) for a, b in outline)) < 1e-6:
        return "the polygon has no area"
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue  # the first and the last edge share vertex 0
            if segments_touch(*outline[i], *outline[j]):
                return f"edges {i} and {j} meet: the polygon must not intersect itself"
    return ""


def on_boundary(point: Point2, vertices: list[Point2]) -> bool:
    """Whether `point` lies on an edge of the polygon."""
    return any(
        _orientation(a, b, point) == 0 and _within_box(a, b, point) for a, b in edges(vertices)
    )


def inside_polygon(point: Point2, vertices: list[Point2]) -> bool:
    """Whether `point` is strictly inside the simple polygon (even-odd ray casting)."""
    if on_boundary(point, vertices):
        return False
    n, e = point
    inside = False
    for (n0, e0), (n1, e1) in edges(vertices):
        if (e0 > e) != (e1 > e):
            crossing_n = n0 + (e - e0) * (n1 - n0) / (e1 - e0)
            if crossing_n > n:
                inside = not inside
    return inside


def segment_inside_polygon(start: Point2, end: Point2, vertices: list[Point2]) -> bool:
    """Whether the whole segment start-end stays strictly inside the simple polygon.

    Both ends inside and no edge touched: a polygon's interior is connected between edges,
    so a segment that meets no edge stays in the region where it starts.
    """
    return (
        inside_polygon(start, vertices)
        and inside_polygon(end, vertices)
        and not any(segments_touch(start, end, a, b) for a, b in edges(vertices))
    )
