"""C-space expansion in disparity space (thesis 4.4.3): front and back disparity images.

Input disparity images use one convention everywhere in wireavoid: `float32 (H, W)` px,
`NaN` = invalid measurement (no evidence), `0` = no stereo return (sky: free out to the sensing
range when `MappingParams.no_return_is_free`), `> 0` = a return, eq. 4.1.

The expansion runs on a grid of `pool_factor`-pixel blocks (conservative max-pooling: the
nearest return of a block stands for the whole block), so node images are small. Output
images `front_px`, `back_px` `(Hc, Wc) float32` on that grid (`DisparityExpander.grid_camera`):
- `front < 0`: unknown (no valid pixel near), no evidence;
- `front == back == 0`: nothing within range: every point on the ray is in front (safe);
- otherwise the ray is occupied for disparities in `[back, front]` (eq. 4.3), `front` may be
  `inf` when the camera is inside the expanded obstacle; a second band `[own_back, own_front]`
  keeps the cell's own farther return visible past the fringe of a nearer obstacle.

Area expansion (Fig. 4.2b): the LUT u -> [u1, u2] (and v -> [v1, v2]) of a sphere of radius
r_v at disparity `d + lambda sigma` is exact per column (tangent planes through the camera
centre); each disparity bin uses the widest window of its LUT over the image (conservative),
applied with separable max/min filters (`cv2.dilate` / `cv2.erode`), at a coarser scale for
the wide windows of near obstacles. Bins are processed near to far; a bin covering a cell
extends the cell's band only when its band touches it (one surface), so the fringe of a near
obstacle hides what lies behind it (potentially safe) instead of filling the gap.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from geometry.camera import PinholeCamera, StereoRig
from mapping.droan.params import MappingParams

# widest morphology window (half-width, cells) run at full grid resolution; wider ones are
# run on a 2^k-pooled grid (conservatively rounded up).
_MAX_DIRECT_HALF_WIDTH = 12
_WIRE_DEPTH_SAMPLES = 64  # depths of the wire prior at which its expansion is evaluated


@dataclass(frozen=True, slots=True)
class ExpansionBin:
    """Disparities in `[low_px, high_px)` expand with window half-widths in grid cells."""

    low_px: float
    high_px: float
    half_width_u: int
    half_width_v: int


@dataclass(frozen=True, slots=True)
class ExpandedImage:
    """Front / back disparity limits on the expansion grid, `(Hc, Wc) float32`, px.

    own_front_px / own_back_px: a second band, the cell's own return, where the expansion of a
    nearer obstacle covers the cell but the cell itself sees a surface farther behind it (the
    space between the two bands is then observed free, not occluded); equal to front / back
    where there is no such second surface. None for wire images.
    """

    front_px: np.ndarray
    back_px: np.ndarray
    own_front_px: np.ndarray | None = None
    own_back_px: np.ndarray | None = None


def expansion_lut(
    camera: PinholeCamera, bf_px_m: float, radius_m: float, disparity_px: np.ndarray, axis: int
) -> tuple[np.ndarray, np.ndarray]:
    """LUT of the area expansion (Fig. 4.2b, after Matthies et al. 2014).

    For a sphere of radius `radius_m` centred on the ray of pixel coordinate c (column when
    `axis == 0`, row when `axis == 1`) at disparity d: the image interval [c1, c2] it covers.
    disparity_px: `(B,)`; returns two `(B, L)` arrays (L = width or height), px, `+-inf` when
    the sphere reaches the camera plane.
    """
    f, c0, length = (
        (camera.fx_px, camera.cx_px, camera.width_px)
        if axis == 0
        else (camera.fy_px, camera.cy_px, camera.height_px)
    )
    d = np.asarray(disparity_px, dtype=np.float64)[:, None]
    z = bf_px_m / d
    theta = np.arctan((np.arange(length) - c0) / f)[None, :]
    rho = z / np.cos(theta)
    alpha = np.arcsin(np.clip(radius_m / rho, 0.0, 1.0))
    lo_angle, hi_angle = theta - alpha, theta + alpha
    with np.errstate(over="ignore"):
        lo = np.where(lo_angle > -np.pi / 2 + 1e-9, c0 + f * np.tan(lo_angle), -np.inf)
        hi = np.where(hi_angle < np.pi / 2 - 1e-9, c0 + f * np.tan(hi_angle), np.inf)
    return lo, hi


def front_disparity(disparity_px: np.ndarray, bf_px_m: float, radius_m: float, margin_px: float):
    """d_f = b f / (z - r_v) + lambda sigma (eq. 4.3); inf where z <= r_v. Same shape, px."""
    d = np.asarray(disparity_px, dtype=np.float32)
    denom = bf_px_m - radius_m * d
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(denom > 0, d * bf_px_m / denom + margin_px, np.inf).astype(np.float32)


def back_disparity(disparity_px: np.ndarray, bf_px_m: float, radius_m: float, margin_px: float):
    """d_b = b f / (z + r_v) - lambda sigma (eq. 4.3), clamped at 0. Same shape, px."""
    d = np.asarray(disparity_px, dtype=np.float32)
    return np.maximum(d * bf_px_m / (bf_px_m + radius_m * d) - margin_px, 0.0).astype(np.float32)


def _pool(image: np.ndarray, factor: int, reduce: np.ufunc, fill: float) -> np.ndarray:
    """Block-reduce `(H, W)` by `factor` with a binary ufunc (`np.fmax`, `np.fmin`, ...),
    padding with `fill`; `(ceil(H / factor), ceil(W / factor))`. Strided, no per-pixel loop.
    """
    if factor == 1:
        return image
    h, w = image.shape
    ph, pw = -h % factor, -w % factor
    if ph or pw:
        image = np.pad(image, ((0, ph), (0, pw)), constant_values=fill)
    columns = image[:, 0::factor].copy()
    for i in range(1, factor):
        reduce(columns, image[:, i::factor], out=columns)
    rows = columns[0::factor].copy()
    for i in range(1, factor):
        reduce(rows, columns[i::factor], out=rows)
    return rows


def _morph(image: np.ndarray, half_u: int, half_v: int, dilate: bool) -> np.ndarray:
    """Rectangular max (dilate) or min (erode) filter of half-widths `(half_u, half_v)` cells.

    Windows wider than `_MAX_DIRECT_HALF_WIDTH` run on a 2^k-pooled grid with the half-width
    rounded up, then are upsampled: the result covers at least the exact window (conservative).
    """
    h, w = image.shape
    half_u, half_v = min(half_u, w), min(half_v, h)
    scale = 1
    while max(half_u, half_v) > _MAX_DIRECT_HALF_WIDTH * scale:
        scale *= 2
    reduce, fill = (np.fmax, -np.inf) if dilate else (np.fmin, np.inf)
    small = _pool(image, scale, reduce, fill) if scale > 1 else image
    ku, kv = -(-half_u // scale), -(-half_v // scale)
    kernel = np.ones((2 * kv + 1, 2 * ku + 1), np.uint8)
    out = (cv2.dilate if dilate else cv2.erode)(small, kernel)
    if scale > 1:
        out = np.repeat(np.repeat(out, scale, axis=0), scale, axis=1)[:h, :w]
    return out


class DisparityExpander:
    """Turns disparity images and wire masks into front/back images (4.4.3, Fig. 4.3, 4.4)."""

    def __init__(self, rig: StereoRig, params: MappingParams) -> None:
        self.rig = rig
        self.params = params
        self.pool_factor = params.pool_factor
        self.grid_camera = rig.camera.scaled(params.pool_factor)
        self.bf_px_m = rig.bf_px_m
        self.margin_px = params.sigma_multiplier * params.disparity_sigma_px
        # returns this far beyond the sensing range (2 sigma) cannot reach into it even with
        # noise: they count as "nothing within range"; nearer ones are expanded as obstacles
        range_px = self.bf_px_m / params.max_range_m
        self.min_disparity_px = max(range_px - 2.0 * params.disparity_sigma_px, 0.25 * range_px)
        self.bins = self._bins()
        self._bin_edges = np.array([b.low_px for b in self.bins], dtype=np.float32)
        wire_disparity = self.bf_px_m / params.wire_depth_near_m
        self.wire_front_px = float(self._front(np.float32(wire_disparity)))
        self.wire_back_px = float(self.bf_px_m / params.wire_depth_far_m)
        self._wire_levels = self._wire_expansion_levels()
        # the nearest disparity of each level's window: the next level's lowest, or the prior's
        self._wire_level_tops = [lvl[2] for lvl in self._wire_levels[1:]] + [wire_disparity]

    def _front(self, disparity_px: np.ndarray) -> np.ndarray:
        return front_disparity(
            disparity_px, self.bf_px_m, self.params.robot_radius_m, self.margin_px
        )

    def _back(self, disparity_px: np.ndarray) -> np.ndarray:
        return back_disparity(
            disparity_px, self.bf_px_m, self.params.robot_radius_m, self.margin_px
        )

    def _half_widths(
        self, lookup_disparity_px: np.ndarray, radius_m: float | None = None
    ) -> list[tuple[int, int]]:
        """Grid-cell window half-widths `(u, v)` for LUT disparities `d + lambda sigma` and an
        expansion radius (default r_v)."""
        camera = self.rig.camera
        r = self.params.robot_radius_m if radius_m is None else radius_m
        halves = []
        for axis in (0, 1):
            lo, hi = expansion_lut(camera, self.bf_px_m, r, lookup_disparity_px, axis)
            coords = np.arange(lo.shape[1])[None, :]
            half_px = np.max(np.maximum(hi - coords, coords - lo), axis=1)
            limit = camera.width_px if axis == 0 else camera.height_px
            half_px = np.minimum(np.ceil(half_px - 1e-9), limit)
            halves.append((-(-half_px // self.pool_factor)).astype(int))
        return [(int(hu), int(hv)) for hu, hv in zip(*halves, strict=True)]

    def _wire_expansion_levels(self) -> list[tuple[int, int, float]]:
        """`(half_u, half_v, back_px)`: the windows of the wire prior's area expansion over its
        depths (eq. 4.3 at each depth of the slab), narrowest (the far limit) first, each with
        the smallest disparity at which its window may already be reached (the previous
        sample's: conservative between samples)."""
        samples = np.linspace(self.wire_back_px, self.bf_px_m / self.params.wire_depth_near_m,
                              _WIRE_DEPTH_SAMPLES)  # fmt: skip
        levels: list[tuple[int, int, float]] = []
        previous = self.wire_back_px
        radius_m = self.params.robot_radius_m + self.params.wire_position_margin_m
        widths = self._half_widths(samples + self.margin_px, radius_m)
        for d, width in zip(samples, widths, strict=True):
            if not levels or width != levels[-1][:2]:
                levels.append((*width, float(previous)))
            previous = float(d)
        return levels

    def _bins(self) -> list[ExpansionBin]:
        """Disparity bins, each narrower than `expansion_bin_fraction` of its band width."""
        fraction = self.params.expansion_bin_fraction
        inside_px = self.bf_px_m / self.params.robot_radius_m  # z <= r_v: camera inside
        edges = [self.min_disparity_px]
        while edges[-1] < inside_px:
            d = np.float32(edges[-1])
            band = float(self._front(d) - self._back(d))
            edges.append(min(edges[-1] + max(fraction * band, 1e-3), inside_px))
        highs = np.array([*edges[1:], np.inf])
        lookup = np.minimum(highs, inside_px) + self.margin_px
        widths = self._half_widths(lookup)
        widths[-1] = (self.grid_camera.width_px, self.grid_camera.height_px)
        return [
            ExpansionBin(float(lo), float(hi), hu, hv)
            for lo, hi, (hu, hv) in zip(edges, highs, widths, strict=True)
        ]

    def pooled_disparity(self, disparity_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Block max and min of the returns within range, on the grid, `(Hc, Wc) float32`.

        Nearest: the largest disparity of the block; 0 where the block has no return within
        range but a free pixel; -1 where all its pixels are invalid (NaN or negative).
        Farthest: the smallest return of the block, the nearest one where the block also holds
        pixels without a return (its edge).
        """
        d = np.asarray(disparity_px, dtype=np.float32)
        if d.shape != self.rig.camera.shape:
            raise ValueError(f"disparity image {d.shape} != camera {self.rig.camera.shape}")
        if self.params.median_filter_px:
            # invalid pixels enter the median as -1 and stay invalid where they dominate
            d = cv2.medianBlur(
                np.where(np.isnan(d), np.float32(-1), d), self.params.median_filter_px
            )
        nearest = _pool(d, self.pool_factor, np.fmax, np.nan)
        farthest = _pool(d, self.pool_factor, np.fmin, np.nan)
        with np.errstate(invalid="ignore"):
            obstacle = nearest >= self.min_disparity_px
            free = nearest >= 0 if self.params.no_return_is_free else nearest > 0
            farthest = np.where(farthest >= self.min_disparity_px, farthest, nearest)
        nearest = np.where(obstacle, nearest, np.where(free, np.float32(0), np.float32(-1)))
        return nearest, np.where(obstacle, farthest, np.float32(np.inf))

    def _wire_pool_factor(self, shape: tuple[int, ...]) -> int:
        """The pooling that takes a wire mask of `shape` onto the expansion grid."""
        h, w = self.rig.camera.shape
        for k in range(1, self.pool_factor + 1):
            if self.pool_factor % k == 0 and shape == (h // k, w // k) and h % k == w % k == 0:
                return self.pool_factor // k
        raise ValueError(
            f"wire mask {shape} is neither the camera's {self.rig.camera.shape} nor an integer "
            f"down-scale of it by a divisor of pool_factor {self.pool_factor}"
        )

    def expand_stereo(self, disparity_px: np.ndarray) -> ExpandedImage:
        """Front/back images of a disparity image `(H, W) float32` px (area + depth, 4.4.3)."""
        nearest, farthest = self.pooled_disparity(disparity_px)
        obstacle = nearest > 0
        # d_f and d_b (eq. 4.3) are increasing in d: the max / min filters can run on them
        block_front = np.where(obstacle, self._front(nearest), np.float32(0))
        far_back = self._back(np.where(obstacle, farthest, 0))
        # a block spanning two separate surfaces keeps only the near one's band; returns of
        # one surface spread by about +-2 sigma of noise within a block
        spread_px = np.float32(4.0 * self.params.disparity_sigma_px)
        block_back = np.where(
            self._front(np.where(obstacle, farthest, 0)) + spread_px >= self._back(nearest),
            far_back,
            self._back(nearest),
        )
        front = np.minimum(nearest, 0).astype(np.float32)
        back = front.copy()
        covered = np.zeros(front.shape, bool)
        bin_of = np.searchsorted(self._bin_edges, nearest, side="right") - 1
        bin_of[~obstacle] = -1
        present = np.flatnonzero(np.bincount(bin_of[bin_of >= 0], minlength=len(self.bins)))
        rows_all, cols_all = front.shape
        for index in present[::-1]:
            b = self.bins[index]
            member = bin_of == index
            rows = np.flatnonzero(member.any(axis=1))
            cols = np.flatnonzero(member.any(axis=0))
            # work on the window that the bin's expansion can reach
            r0, r1 = max(rows[0] - b.half_width_v, 0), min(rows[-1] + b.half_width_v + 1, rows_all)
            c0, c1 = max(cols[0] - b.half_width_u, 0), min(cols[-1] + b.half_width_u + 1, cols_all)
            window = (slice(r0, r1), slice(c0, c1))
            inside = member[window]
            near = _morph(
                np.where(inside, block_front[window], np.float32(0)),
                b.half_width_u,
                b.half_width_v,
                dilate=True,
            )
            far = _morph(
                np.where(inside, block_back[window], np.float32(np.inf)),
                b.half_width_u,
                b.half_width_v,
                dilate=False,
            )
            hit = near > 0
            done = covered[window]
            new = hit & ~done
            w_front, w_back = front[window], back[window]
            touching = hit & done & (near >= w_back)
            w_front[new] = near[new]
            w_back[new] = far[new]
            w_back[touching] = np.minimum(w_back[touching], far[touching])
            done |= hit
        # the cell's own return, when it lies behind the band covering the cell
        own = obstacle & (block_front < back)
        return ExpandedImage(
            front, back, np.where(own, block_front, front), np.where(own, block_back, back)
        )

    def pooled_wire_mask(self, wire_mask: np.ndarray) -> np.ndarray:
        """`(Hc, Wc) bool` grid cells holding a pixel of the mask (shapes as `expand_wire`)."""
        mask = np.asarray(wire_mask, dtype=bool)
        return _pool(mask, self._wire_pool_factor(mask.shape), np.logical_or, False)

    def expand_wire(
        self, wire_mask: np.ndarray, spans_m: tuple[np.ndarray, np.ndarray] | None = None
    ) -> ExpandedImage:
        """Front/back images of a binary wire mask (4.4.3, Fig. 4.4).

        wire_mask: `(H, W) bool` on the disparity camera's pixels, or `(H / k, W / k)` for an
            integer k dividing `pool_factor`: a colour camera registered to the disparity
            camera at a k-times lower resolution (the CNN's input size), pooled by
            `pool_factor / k` onto the same grid.
        spans_m: `(Hc, Wc)` near and far depth of each wire cell's ray on the grid, m
            (`wire_depth`); None: the depth prior [`wire_depth_near_m`, `wire_depth_far_m`]
            everywhere.
        Wire cells span their depths; the front is the near limit depth-expanded like a stereo
        return. The area expansion is the one of eq. 4.3 at each depth of the span, not only
        at its near limit (beyond the thesis): a cell the expansion reaches only at nearer
        depths has its back limit there. At the near limit's width throughout, a wire (or a
        false one on the horizon) 10-20 m away filled a wedge two to five times the vehicle's
        size, which views from a metre higher or lower could not vote away (the vehicle climbed
        after it, 10 m in the fault field). Cells away from any wire are 0 (no wire).
        """
        pooled = self.pooled_wire_mask(wire_mask)
        prior = pooled if spans_m is None else pooled & ~self._is_cut(*spans_m)
        back = np.zeros(pooled.shape, np.float32)
        reached, reach_u, reach_v = prior.astype(np.float32), 0, 0
        for half_u, half_v, back_px in self._wire_levels:  # nested windows: grow step by step
            reached = _morph(reached, half_u - reach_u, half_v - reach_v, dilate=True)
            reach_u, reach_v = half_u, half_v
            back[(reached > 0) & (back == 0)] = back_px
        front = np.where(back > 0, np.float32(self.wire_front_px), np.float32(0))
        if spans_m is not None and (cut := pooled & ~prior).any():
            cut_front, cut_back = self._expand_spans(cut, *spans_m)
            hit = cut_front > 0
            front = np.maximum(front, cut_front)
            back[hit] = np.where(back[hit] > 0, np.minimum(back[hit], cut_back[hit]), cut_back[hit])
        return ExpandedImage(front, back)

    def _is_cut(self, near_m: np.ndarray, far_m: np.ndarray) -> np.ndarray:
        """`(Hc, Wc) bool`: a span narrower than the depth prior."""
        with np.errstate(invalid="ignore"):
            return (near_m > self.params.wire_depth_near_m) | (far_m < self.params.wire_depth_far_m)

    def _expand_spans(
        self, cells: np.ndarray, near_m: np.ndarray, far_m: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Front and back images (0 where unreached) of the wire `cells` whose rays span
        [`near_m`, `far_m`]: each level's window (eq. 4.3 at its depths) around the cells
        whose span reaches into the level's depths, with the span's depths clipped to them."""
        bf = np.float32(self.bf_px_m)
        span_front = np.where(cells, bf / np.where(cells, near_m, 1).astype(np.float32), 0)
        span_back = np.where(cells, bf / np.where(cells, far_m, 1).astype(np.float32), np.inf)
        front = np.zeros(cells.shape, np.float32)
        back = np.full(cells.shape, np.inf, np.float32)
        for (half_u, half_v, low_px), high_px in zip(
            self._wire_levels, self._wire_level_tops, strict=True
        ):
            inside = cells & (span_back <= high_px) & (span_front >= low_px)
            if not inside.any():
                continue
            nearest = np.where(inside, np.minimum(span_front, high_px), np.float32(0))
            farthest = np.where(inside, np.maximum(span_back, low_px), np.float32(np.inf))
            front = np.maximum(front, _morph(nearest, half_u, half_v, dilate=True))
            back = np.minimum(back, _morph(farthest, half_u, half_v, dilate=False))
        reached = front > 0
        return (
            np.where(reached, self._front(front), np.float32(0)).astype(np.float32),
            np.where(reached, back, np.float32(0)).astype(np.float32),
        )
