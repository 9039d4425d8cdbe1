"""Surface textures of the simulated world, mapped in world coordinates, with mipmaps.

Each material of `hil.world.materials` gets one periodic (seamless) `TILE_PX` x `TILE_PX`
linear-RGB tile, drawn from the world's seed: procedural patterns (fractal value noise, grass,
gravel, bricks, wood grain, foliage), or a real photograph of that material when the photo pool
has one (a photo whose file is named like the material, e.g. skimage's `brick.png`,
`grass.png`, `gravel.png`; the real-photo test set is excluded by `PhotoPool`). A surface
point at texture coordinates (a, b) (m, along the surface) shows texel
`(floor(b / texel_m), floor(a / texel_m)) mod TILE_PX`, the same from every pose; the mip level
follows the pixel's footprint on the surface so distant textures average instead of aliasing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from hil.world.materials import MATERIALS, Material

TILE_PX = 256
LEVELS = 9  # 256 .. 1 px


def periodic_noise(
    rng: np.random.Generator, size_px: int, cells: int, cells_across: int | None = None
) -> np.ndarray:
    """`(size, size) float32` periodic value noise in [0, 1] with `cells` random knots down
    and `cells_across` (default `cells`) across."""
    grid = rng.random((cells, cells_across or cells)).astype(np.float32)
    tiled = np.tile(grid, (3, 3))
    big = cv2.resize(tiled, (3 * size_px, 3 * size_px), interpolation=cv2.INTER_CUBIC)
    return big[size_px : 2 * size_px, size_px : 2 * size_px]


def fractal(rng: np.random.Generator, size_px: int, base_cells: int, octaves: int) -> np.ndarray:
    """`(size, size) float32` periodic fractal noise in [0, 1] (octaves of `periodic_noise`)."""
    out = np.zeros((size_px, size_px), np.float32)
    amplitude, cells = 1.0, base_cells
    for _ in range(octaves):
        out += amplitude * periodic_noise(rng, size_px, min(cells, size_px))
        amplitude *= 0.55
        cells *= 2
    out -= out.min()
    return out / max(float(out.max()), 1e-6)


def _pattern(rng: np.random.Generator, pattern: str, n: int) -> np.ndarray:
    """`(n, n) float32` zero-mean, unit-ish amplitude pattern; rows run down walls."""
    if pattern == "flat":
        return np.zeros((n, n), np.float32)
    if pattern == "noise":  # mottling at every scale down to the texel's grain
        spots = periodic_noise(rng, n, n // 8) + periodic_noise(rng, n, n // 4) - 1.0
        grain = rng.random((n, n), dtype=np.float32) - 0.5
        return fractal(rng, n, 4, 6) - 0.5 + 0.5 * spots + 0.35 * grain
    if pattern == "grass":
        blades = periodic_noise(rng, n, n // 2) - 0.5
        patches = fractal(rng, n, 4, 4) - 0.5
        return 0.6 * blades + 0.8 * patches
    if pattern == "gravel":
        stones = periodic_noise(rng, n, n // 3)
        return 1.2 * (stones - 0.5) + 0.4 * (fractal(rng, n, 8, 3) - 0.5)
    if pattern == "grain":
        # streaks running down (along the rows' axis): wood grain and bark of poles, trunks
        streaks = periodic_noise(rng, n, 4, n // 2)
        knots = fractal(rng, n, 4, 3)
        return 1.0 * (streaks - 0.5) + 0.5 * (knots - 0.5)
    if pattern == "foliage":
        leaves = periodic_noise(rng, n, n // 4)
        clumps = fractal(rng, n, 4, 4)
        return 1.3 * (leaves - 0.5) + 0.9 * (clumps - 0.5)
    if pattern == "brick":
        # courses 16 texels high, bricks 64 texels long (at 3.4 mm texels: 5.4 x 22 cm),
        # 1-texel mortar joints, every other course offset by half a brick
        rows, cols = np.mgrid[0:n, 0:n]
        course = rows // 16
        shifted = (cols + (course % 2) * 32) % n
        brick_id = course * 8 + shifted // 64
        per_brick = rng.normal(0.0, 0.35, brick_id.max() + 1).astype(np.float32)
        face = per_brick[brick_id] + 0.4 * (fractal(rng, n, 16, 3) - 0.5)
        mortar = (rows % 16 == 0) | (shifted % 64 == 0)
        return np.where(mortar, 0.9, face).astype(np.float32)
    raise ValueError(f"unknown texture pattern {pattern!r}")


def _photo_tile(photo_rgb: np.ndarray, n: int) -> np.ndarray:
    """`(n, n)` seamless linear-RGB tile from a photograph, mean 1 per channel: the centre
    square resized, blended with its half-shifted copy towards the borders."""
    h, w = photo_rgb.shape[:2]
    side = min(h, w)
    crop = photo_rgb[(h - side) // 2 : (h + side) // 2, (w - side) // 2 : (w + side) // 2]
    tile = cv2.resize(crop, (n, n), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    tile = tile**2.2  # sRGB-ish to linear
    ramp = 1.0 - np.abs(np.arange(n) - (n - 1) / 2) / ((n - 1) / 2)  # 1 centre, 0 borders
    weight = np.minimum.outer(ramp, ramp)[..., None]
    shifted = np.roll(tile, (n // 2, n // 2), axis=(0, 1))
    seamless = weight * tile + (1 - weight) * shifted
    return seamless / np.maximum(seamless.mean(axis=(0, 1), keepdims=True), 1e-3)


def material_tile(
    material: Material, rng: np.random.Generator, photo_rgb: np.ndarray | None = None
) -> np.ndarray:
    """`(TILE_PX, TILE_PX, 3) float32` linear-RGB albedo tile of `material` (see module)."""
    base = np.asarray(material.rgb, np.float32)
    if photo_rgb is not None:
        return np.clip(_photo_tile(photo_rgb, TILE_PX) * base, 0.0, 1.0)
    pattern = _pattern(rng, material.pattern, TILE_PX)
    # slow hue shifts across the tile: each channel follows the same field with its own gain
    hue = fractal(rng, TILE_PX, 2, 2)[..., None] - 0.5
    gains = rng.normal(0.0, 0.25, 3).astype(np.float32)
    rgb = base * (1.0 + material.contrast * pattern[..., None]) * (1.0 + hue * gains)
    return np.clip(rgb, 0.0, 1.0).astype(np.float32)


@dataclass(frozen=True)
class TextureAtlas:
    """The mip pyramids of every material's tile in one flat `(T, 3) float32` array.

    offsets: `(M, LEVELS) int64` start of each material's level in `texels`;
    index: material name -> row of `offsets`; texel_m: `(M,)` texel size, m.
    """

    texels: np.ndarray
    offsets: np.ndarray
    index: dict[str, int]
    texel_m: np.ndarray

    @classmethod
    def build(cls, seed: int, photos: dict[str, np.ndarray] | None = None) -> TextureAtlas:
        """Tiles for every material from `seed`; `photos` maps material names to RGB uint8
        photographs to use instead of the procedural pattern."""
        photos = photos or {}
        chunks, offsets, index = [], [], {}
        total = 0
        for k, (name, material) in enumerate(sorted(MATERIALS.items())):
            rng = np.random.default_rng([seed, k])
            level = material_tile(material, rng, photos.get(name))
            row = []
            for _ in range(LEVELS):
                row.append(total)
                chunks.append(level.reshape(-1, 3))
                total += level.shape[0] * level.shape[1]
                level = cv2.resize(
                    level,
                    (max(level.shape[1] // 2, 1), max(level.shape[0] // 2, 1)),
                    interpolation=cv2.INTER_AREA,
                ).reshape(max(level.shape[0] // 2, 1), max(level.shape[1] // 2, 1), 3)
            offsets.append(row)
            index[name] = k
        texel = np.array([MATERIALS[n].texel_m for n in sorted(MATERIALS)])
        return cls(np.concatenate(chunks), np.array(offsets, np.int64), index, texel)

    def sample(
        self, material: np.ndarray, a_m: np.ndarray, b_m: np.ndarray, footprint_m: np.ndarray
    ) -> np.ndarray:
        """`(N, 3) float32` albedo at surface coordinates `a_m`, `b_m` (N,) (m) of materials
        `material` (N,) (rows of `offsets`) seen with a pixel footprint `footprint_m` (N,),
        m: nearest texel of the mip level whose texel is closest to the footprint."""
        texel = self.texel_m[material]
        ratio = np.maximum(footprint_m / texel, 1.0)
        level = np.minimum(np.log2(ratio).astype(np.int64), LEVELS - 1)
        col = np.floor(a_m / texel).astype(np.int64) >> level
        row = np.floor(b_m / texel).astype(np.int64) >> level
        size = TILE_PX >> level
        mask = size - 1
        flat = self.offsets[material, level] + (row & mask) * size + (col & mask)
        return self.texels[flat]


def photo_textures(sources: list[str]) -> dict[str, np.ndarray]:
    """Material name -> RGB photo, from the `PhotoPool` of `sources` ('skimage' or folders):
    photos whose file stem is a material name (the real-photo test set is never used)."""
    if not sources:
        return {}
    from perception.training.backgrounds import PhotoPool

    pool = PhotoPool.load(sources)
    out = {}
    for name, image in zip(pool.names, pool.images, strict=True):
        stem = Path(name.split(":", 1)[-1]).stem
        if stem in MATERIALS and stem not in out:
            out[stem] = image
    return out
