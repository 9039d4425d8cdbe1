"""Backgrounds for synthetic wire images (thesis 2.3.2): procedural scenes and real photographs.

The thesis superimposed wires on frames of flight videos. Here the backgrounds are either
procedural (sky gradient, clouds, hills, tree lines, fields and vegetation-like texture, with
strong straight-edge distractors: poles, rail fences, roofs, building edges, road markings,
branches) or real photographs from a pool (``PhotoPool``: scikit-image's bundled sample images
when that package is installed, plus any folders given), optionally with the same distractors.
Nothing drawn here is ever labelled wire. All images are float32 (H, W, 3) RGB in [0, 1];
every random choice comes from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from perception.training.real_photos import training_exclusions

SKIMAGE_PHOTOS = (
    "astronaut.png",
    "brick.png",
    "chelsea.png",
    "coffee.png",
    "grass.png",
    "gravel.png",
    "motorcycle_left.png",
    "rocket.jpg",
    "camera.png",
)
"""Photographs bundled in the scikit-image wheel (no download; public domain / CC0, see the
package's data/README and docs) used as backgrounds and ground textures when it is installed."""

_PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".webp")
TREE_LINE_PROBABILITY = 0.6
"""Share of procedural landscapes with a tree line on the horizon."""


@dataclass(frozen=True)
class Horizon:
    """Image line of the horizon: v = v_center_px + slope * (u - W/2); below it is ground.
    `focal_px` is the camera's focal length (0 where unknown)."""

    v_center_px: float
    slope: float
    focal_px: float = 0.0


class PhotoPool:
    """Real photographs as RGB uint8 arrays, each downscaled so its long side is <= 1024 px."""

    def __init__(self, images: list[np.ndarray], names: list[str]) -> None:
        self.images = images
        self.names = names

    def __len__(self) -> int:
        return len(self.images)

    @classmethod
    def load(cls, sources: list[str], excluded: frozenset[str] | None = None) -> PhotoPool:
        """Pool from sources: 'skimage' (bundled sample photos if installed) or folders.

        Photos whose SHA-256 is in `excluded` are left out; by default, the real-photo test set
        and photos with unlabelled wires (`perception.training.real_photos.training_exclusions`).
        """
        if excluded is None:
            excluded = training_exclusions()
        images, names = [], []
        for source in sources:
            for path in _source_files(source):
                data = path.read_bytes()
                if hashlib.sha256(data).hexdigest() in excluded:
                    continue
                bgr = (
                    cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR) if data else None
                )
                if bgr is None or min(bgr.shape[:2]) < 64:
                    continue
                scale = min(1.0, 1024 / max(bgr.shape[:2]))
                if scale < 1.0:
                    bgr = cv2.resize(bgr, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
                images.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
                names.append(f"{source}:{path.name}")
        return cls(images, names)


def _source_files(source: str) -> list[Path]:
    """Image files of one photo source, sorted for determinism."""
    if source == "skimage":
        try:
            import skimage
        except ImportError:
            return []
        data_dir = Path(skimage.__file__).parent / "data"
        return [data_dir / n for n in SKIMAGE_PHOTOS if (data_dir / n).exists()]
    root = Path(os.path.expanduser(source))
    return sorted(p for p in root.rglob("*") if p.suffix.lower() in _PHOTO_SUFFIXES)


def fractal_noise(rng: np.random.Generator, h: int, w: int, base_cells: int = 3) -> np.ndarray:
    """Multi-octave value noise (H, W) float32 normalised to [0, 1]; base_cells sets the scale."""
    out = np.zeros((h, w), np.float32)
    amplitude, cells = 1.0, base_cells
    while cells < max(h, w) // 2:
        grid = rng.random((cells + 1, cells * w // max(h, 1) + 2)).astype(np.float32)
        out += amplitude * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        amplitude *= 0.55
        cells *= 2
    out -= out.min()
    return out / max(float(out.max()), 1e-6)


def below_horizon(h: int, w: int, horizon: Horizon, bumps: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool, True below the horizon line (optionally raised by per-column bumps, px)."""
    u = np.arange(w, dtype=np.float32)
    v_line = horizon.v_center_px + horizon.slope * (u - w / 2)
    if bumps is not None:
        v_line = v_line - bumps
    return np.arange(h, dtype=np.float32)[:, None] > v_line[None, :]


def _ridge(rng: np.random.Generator, w: int, height_px: float, roughness: int) -> np.ndarray:
    """1D fractal silhouette (W,) in [0, height_px] for hills and tree lines."""
    u = np.arange(w, dtype=np.float64)
    out = np.zeros(w)
    amplitude, cells = 1.0, max(roughness, 1)
    while cells <= w:
        knots = rng.random(cells + 1)
        out += amplitude * np.interp(u * cells / max(w - 1, 1), np.arange(cells + 1), knots)
        amplitude *= 0.55
        cells *= 2
    out -= out.min()
    return (out / max(out.max(), 1e-9) * height_px).astype(np.float32)


def sky(
    rng: np.random.Generator,
    h: int,
    w: int,
    horizon: Horizon,
    perspective_cloud_probability: float = 0.0,
) -> np.ndarray:
    """Sky: vertical gradient (clear, overcast, hazy, sunset or dusk) with fractal clouds, which
    with `perspective_cloud_probability` lie on a layer far above (`perspective_clouds`)."""
    kind = rng.choice(
        ["clear", "overcast", "hazy", "sunset", "dusk"], p=[0.4, 0.25, 0.15, 0.1, 0.1]
    )
    zenith, horizon_rgb = {
        "clear": ([0.15, 0.35, 0.75], [0.7, 0.82, 0.95]),
        "overcast": ([0.55, 0.57, 0.6], [0.8, 0.8, 0.82]),
        "hazy": ([0.7, 0.75, 0.8], [0.92, 0.92, 0.9]),
        "sunset": ([0.25, 0.3, 0.55], [0.98, 0.6, 0.3]),
        "dusk": ([0.05, 0.07, 0.2], [0.4, 0.3, 0.35]),
    }[str(kind)]
    jitter = rng.normal(0, 0.06, (2, 3))
    zenith_c = np.clip(np.asarray(zenith) + jitter[0], 0, 1)
    horizon_c = np.clip(np.asarray(horizon_rgb) + jitter[1], 0, 1)
    v = np.arange(h, dtype=np.float32)[:, None] - horizon.v_center_px
    t = np.clip(1.0 + v / max(h * rng.uniform(0.6, 1.5), 1), 0, 1)[..., None] ** 1.5
    img = np.broadcast_to(zenith_c * (1 - t) + horizon_c * t, (h, w, 3)).astype(np.float32)
    if rng.random() < 0.7:
        perspective = perspective_cloud_probability > 0 and horizon.focal_px > 0
        if perspective and rng.random() < perspective_cloud_probability:
            cover = perspective_clouds(rng, h, w, horizon)
        else:
            cover = fractal_noise(rng, h, w, base_cells=int(rng.integers(2, 6)))
        edge = rng.uniform(0.35, 0.7)
        alpha = np.clip((cover - edge) / rng.uniform(0.05, 0.3), 0, 1)[..., None]
        cloud_c = rng.uniform(0.6, 1.0) * np.array([1.0, 1.0, 1.0]) - rng.uniform(0, 0.15)
        shade = 1.0 - 0.35 * fractal_noise(rng, h, w, base_cells=4)[..., None]
        img = img * (1 - alpha) + (cloud_c * shade) * alpha
    return img.astype(np.float32)


def perspective_clouds(rng: np.random.Generator, h: int, w: int, horizon: Horizon) -> np.ndarray:
    """Cloud density (H, W) in [0, 1] of a layer far above, seen in perspective.

    A ray `e` above the horizon meets a layer at height H after H / tan(e) ahead, so a pixel d
    px above the horizon and a px along it sees the layer at (a / d, f / d) H (f the focal
    length): clouds flatten into horizontal streaks with sharp lower edges towards the
    horizon, as real ones do. Density fades into the horizon haze below a few degrees.
    """
    tile_px, ss = 256, 3  # the tile's detail stops at 4 texels; supersampled ss x ss
    coarse = fractal_noise(rng, tile_px // 4, tile_px // 4, base_cells=int(rng.integers(2, 5)))
    tile = cv2.resize(coarse, (tile_px, tile_px), interpolation=cv2.INTER_CUBIC)
    cos_t = 1.0 / np.hypot(1.0, horizon.slope)
    u = (np.arange(w * ss, dtype=np.float32)[None, :] + 0.5) / ss - w / 2
    v = (np.arange(h * ss, dtype=np.float32)[:, None] + 0.5) / ss - horizon.v_center_px
    above = (horizon.slope * u - v) * cos_t  # px above the horizon line
    along = (u + horizon.slope * v) * cos_t
    d = np.maximum(above, 0.5)
    scale = tile_px * rng.uniform(0.1, 0.5)  # layer height over the tile's size
    x = scale * along / d + rng.uniform(0, tile_px)
    y = scale * horizon.focal_px / d + rng.uniform(0, tile_px)
    # mirror the tile so that any coordinate samples it without a seam
    x, y = (tile_px - 1 - np.abs(np.mod(c, 2 * tile_px - 2) - (tile_px - 1)) for c in (x, y))
    density = cv2.remap(tile, x.astype(np.float32), y.astype(np.float32), cv2.INTER_LINEAR)
    fade = np.clip(above / (horizon.focal_px * rng.uniform(0.03, 0.12)), 0, 1)
    return cv2.resize(density * fade, (w, h), interpolation=cv2.INTER_AREA)


def _palette_texture(
    rng: np.random.Generator, h: int, w: int, colours: np.ndarray, base_cells: int
) -> np.ndarray:
    """Texture (H, W, 3) mixing palette colours by fractal noise, with fine grain."""
    n = fractal_noise(rng, h, w, base_cells)
    idx = n * (len(colours) - 1)
    lo = np.floor(idx).astype(np.int32)
    hi = np.minimum(lo + 1, len(colours) - 1)
    frac = (idx - lo)[..., None]
    img = colours[lo] * (1 - frac) + colours[hi] * frac
    grain = rng.normal(0, rng.uniform(0.01, 0.06), (h, w, 1)).astype(np.float32)
    return np.clip(img + grain, 0, 1).astype(np.float32)


def vegetation(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Vegetation-like texture: fractal greens with leafy blobs of light and shadow."""
    base = np.array([0.12, 0.25, 0.08]) * rng.uniform(0.6, 1.4) + rng.normal(0, 0.03, 3)
    colours = np.clip(np.stack([base * 0.4, base, base * 1.6, base * 0.8 + 0.1]), 0, 1)
    img = _palette_texture(rng, h, w, colours.astype(np.float32), int(rng.integers(4, 12)))
    n_blobs = int(h * w / rng.uniform(60, 200))
    centres = np.stack([rng.integers(0, w, n_blobs), rng.integers(0, h, n_blobs)], 1)
    leaf = np.zeros((h, w), np.float32)
    for (cx, cy), r, val in zip(
        centres, rng.integers(1, 4, n_blobs), rng.uniform(-1, 1, n_blobs), strict=True
    ):
        cv2.circle(leaf, (int(cx), int(cy)), int(r), float(val), -1)
    return np.clip(img * (1 + 0.35 * leaf[..., None]), 0, 1).astype(np.float32)


def terrain(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Ground texture: fields, earth, crops, rock, snow or urban grey."""
    kind = rng.choice(["field", "earth", "crop", "rock", "urban", "snow", "vegetation"])
    if kind == "vegetation":
        return vegetation(rng, h, w)
    base = {
        "field": [0.3, 0.45, 0.15],
        "earth": [0.4, 0.3, 0.2],
        "crop": [0.7, 0.6, 0.3],
        "rock": [0.45, 0.43, 0.4],
        "urban": [0.4, 0.4, 0.42],
        "snow": [0.85, 0.87, 0.9],
    }[str(kind)]
    base = np.clip(np.asarray(base) + rng.normal(0, 0.05, 3), 0, 1)
    colours = np.clip(np.stack([base * 0.6, base, base * 1.25]), 0, 1).astype(np.float32)
    return _palette_texture(rng, h, w, colours, int(rng.integers(2, 10)))


def photo_crop(rng: np.random.Generator, pool: PhotoPool, h: int, w: int) -> np.ndarray:
    """A random crop of a random photograph, rescaled, maybe flipped and colour-jittered."""
    photo = pool.images[int(rng.integers(len(pool)))]
    ph, pw = photo.shape[:2]
    scale = rng.uniform(1.0, 2.5) * max(h / ph, w / pw)
    ch, cw = min(ph, int(np.ceil(h / scale))), min(pw, int(np.ceil(w / scale)))
    y0, x0 = int(rng.integers(0, ph - ch + 1)), int(rng.integers(0, pw - cw + 1))
    crop = cv2.resize(photo[y0 : y0 + ch, x0 : x0 + cw], (w, h), interpolation=cv2.INTER_LINEAR)
    if rng.random() < 0.5:
        crop = crop[:, ::-1]
    img = crop.astype(np.float32) / 255.0
    return np.clip(img * rng.uniform(0.85, 1.15, 3) + rng.normal(0, 0.03), 0, 1).astype(np.float32)


def _fill_below(img: np.ndarray, layer: np.ndarray, mask: np.ndarray) -> None:
    """Paint layer into img where mask is True, in place."""
    img[mask] = layer[mask]


def landscape(
    rng: np.random.Generator,
    h: int,
    w: int,
    horizon: Horizon,
    pool: PhotoPool | None,
    tree_line_probability: float = TREE_LINE_PROBABILITY,
    perspective_cloud_probability: float = 0.0,
) -> np.ndarray:
    """Sky over hills, a tree line (with `tree_line_probability`) and textured ground, each
    layer with its own silhouette."""
    img = sky(rng, h, w, horizon, perspective_cloud_probability)
    for _ in range(int(rng.integers(0, 3))):
        hills = _ridge(rng, w, rng.uniform(5, h * 0.25), int(rng.integers(2, 8)))
        haze = rng.uniform(0.2, 0.7)
        colour = img[int(np.clip(horizon.v_center_px, 0, h - 1)), w // 2]
        layer = terrain(rng, h, w) * (1 - haze) + colour * haze
        _fill_below(img, layer, below_horizon(h, w, horizon, hills))
    if rng.random() < tree_line_probability:
        trees = _ridge(rng, w, rng.uniform(3, h * 0.2), int(rng.integers(20, 80)))
        _fill_below(
            img, vegetation(rng, h, w) * rng.uniform(0.5, 1.0), below_horizon(h, w, horizon, trees)
        )
    use_photo = pool is not None and len(pool) > 0 and rng.random() < 0.35
    ground = photo_crop(rng, pool, h, w) if use_photo else terrain(rng, h, w)
    _fill_below(img, ground, below_horizon(h, w, horizon))
    return img


def draw_pole(
    img: np.ndarray, top_uv: np.ndarray, bottom_uv: np.ndarray, width_px: float, rgb: np.ndarray
) -> None:
    """Draw a pole (thick anti-aliased segment) between two image points, in place."""
    thickness = int(np.clip(round(width_px), 1, 60))
    pts = np.round(np.stack([top_uv, bottom_uv]) * 16).astype(np.int32)
    cv2.line(img, tuple(pts[0]), tuple(pts[1]), rgb.tolist(), thickness, cv2.LINE_AA, shift=4)


def add_distractors(rng: np.random.Generator, img: np.ndarray, horizon: Horizon) -> None:
    """Straight-edge distractors, never labelled wire: poles, rail fences, roofs, buildings,
    road markings and branches, drawn in place (2.3.2's hard negatives)."""
    h, w = img.shape[:2]
    tilt = horizon.slope
    for _ in range(int(rng.poisson(1.2))):
        kind = rng.choice(["pole", "fence", "roof", "building", "road", "branch"])
        rgb = np.clip(rng.uniform(0.05, 0.8) + rng.normal(0, 0.08, 3), 0, 1)
        y_low = float(np.clip(horizon.v_center_px - h * 0.2, -h * 0.2, h * 0.8))
        x, y = rng.uniform(0, w), rng.uniform(y_low, h)
        if kind == "pole":
            top = np.array([x + rng.normal(0, 5), rng.uniform(-h * 0.3, y)])
            draw_pole(img, top, np.array([x, h + 5.0]), rng.uniform(2.5, 18), rgb)
        elif kind == "fence":
            posts = np.arange(rng.uniform(-50, 0), w + 50, rng.uniform(15, 80))
            rail_dy = rng.uniform(4, 20)
            for px in posts:
                draw_pole(img, np.array([px, y - rail_dy * 2.5]), np.array([px, y]), 3.0, rgb)
            for k in range(int(rng.integers(2, 4))):
                yy = y - rail_dy * k - 1
                left, right = np.array([0.0, yy - tilt * w / 2]), np.array([w, yy + tilt * w / 2])
                draw_pole(img, left, right, rng.uniform(2.5, 5), rgb)
        elif kind in ("roof", "building"):
            bw, bh = rng.uniform(0.15, 0.7) * w, rng.uniform(0.1, 0.5) * h
            x0, base = x - bw / 2, min(y + bh, h + 10)
            body = np.array([[x0, base], [x0 + bw, base], [x0 + bw, base - bh], [x0, base - bh]])
            cv2.fillPoly(img, [np.round(body * 16).astype(np.int32)], rgb.tolist(), cv2.LINE_AA, 4)
            if kind == "roof":
                apex = np.array(
                    [x + rng.normal(0, bw * 0.1), base - bh - rng.uniform(0.1, 0.4) * bw]
                )
                roof = np.stack([body[3] - [bw * 0.05, 0], body[2] + [bw * 0.05, 0], apex])
                roof_rgb = np.clip(rgb * rng.uniform(0.4, 1.5), 0, 1).tolist()
                cv2.fillPoly(img, [np.round(roof * 16).astype(np.int32)], roof_rgb, cv2.LINE_AA, 4)
            else:
                win = np.clip(rgb * rng.uniform(0.2, 0.6), 0, 1).tolist()
                step = rng.uniform(8, 25)
                for wx in np.arange(x0 + step / 2, x0 + bw - step / 2, step):
                    for wy in np.arange(base - bh + step / 2, base - step / 2, step * 1.3):
                        cv2.rectangle(
                            img,
                            (int(wx), int(wy)),
                            (int(wx + step / 2), int(wy + step / 2)),
                            win,
                            -1,
                        )
        elif kind == "road":
            # Markings taper to the vanishing point, as ground lines seen in perspective do.
            vanish = np.array([w / 2 + rng.normal(0, w / 4), horizon.v_center_px])
            paint = np.clip(rng.uniform(0.7, 1.0) * np.array([1.0, 1.0, rng.uniform(0.6, 1)]), 0, 1)
            for dx in rng.uniform(-w, 2 * w, int(rng.integers(1, 4))):
                half = rng.uniform(4, 20)
                strip = np.array([vanish, [dx - half, h + 5.0], [dx + half, h + 5.0]])
                cv2.fillPoly(
                    img, [np.round(strip * 16).astype(np.int32)], paint.tolist(), cv2.LINE_AA, 4
                )
        else:
            start = np.array([x, y])
            for _ in range(int(rng.integers(3, 8))):
                end = start + rng.normal(0, 25, 2)
                draw_pole(img, start, end, rng.uniform(1.5, 4), rgb * 0.5)
                start = end


def background(
    rng: np.random.Generator,
    h: int,
    w: int,
    horizon: Horizon,
    pool: PhotoPool | None = None,
    photo_probability: float = 0.3,
    tree_line_probability: float = TREE_LINE_PROBABILITY,
    perspective_cloud_probability: float = 0.0,
) -> tuple[np.ndarray, bool]:
    """A random background (H, W, 3) float32 in [0, 1] and whether it is a photograph (when the
    pool has any, with photo_probability) rather than a procedural landscape, whose ground lies
    below the horizon; plus straight-edge distractors."""
    photo = pool is not None and len(pool) > 0 and rng.random() < photo_probability
    if photo:
        img = photo_crop(rng, pool, h, w)  # type: ignore[arg-type]
    else:
        img = landscape(
            rng, h, w, horizon, pool, tree_line_probability, perspective_cloud_probability
        )
    img = np.ascontiguousarray(img, dtype=np.float32)
    add_distractors(rng, img, horizon)
    return img, photo
