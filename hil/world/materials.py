"""Surface materials of the simulated world: the colour and the texture each surface carries.

A material is world data (a brick wall is red-brown whatever looks at it); the pixels of its
texture are made by `hil.sensors.textures`, mapped in world coordinates so that the same surface
point looks the same from every pose. Colours are linear RGB albedos in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Material:
    """A surface's look: mean linear-RGB albedo `rgb`, texture `pattern` (a generator of
    `hil.sensors.textures`), its `contrast` (relative amplitude, 0 = uniform: stereo finds no
    texture there) and `texel_m`, the world size of one texture cell (m)."""

    name: str
    rgb: tuple[float, float, float]
    pattern: str
    contrast: float
    texel_m: float


MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        Material("grass", (0.11, 0.20, 0.06), "grass", 0.55, 0.02),
        Material("dry_grass", (0.30, 0.26, 0.12), "grass", 0.5, 0.02),
        Material("soil", (0.22, 0.16, 0.10), "noise", 0.45, 0.02),
        Material("gravel", (0.30, 0.29, 0.27), "gravel", 0.6, 0.01),
        Material("asphalt", (0.10, 0.10, 0.11), "gravel", 0.35, 0.01),
        Material("concrete", (0.45, 0.44, 0.41), "noise", 0.45, 0.02),
        Material("brick", (0.36, 0.16, 0.10), "brick", 0.45, 0.0034),
        Material("plaster", (0.62, 0.58, 0.52), "noise", 0.05, 0.04),
        Material("plain", (0.55, 0.55, 0.55), "flat", 0.0, 0.1),
        Material("wood", (0.33, 0.22, 0.12), "grain", 0.4, 0.01),
        Material("metal", (0.50, 0.51, 0.53), "noise", 0.3, 0.01),
        Material("foliage", (0.06, 0.13, 0.04), "foliage", 0.8, 0.03),
        Material("bark", (0.16, 0.11, 0.08), "grain", 0.5, 0.01),
    )
}
"""Every material a world may name (the world file's `material` keys), by name."""

GROUND_MATERIALS = ("grass", "dry_grass", "soil", "gravel", "asphalt", "concrete")
"""Materials that make a plausible ground (the scenarios draw from these)."""
