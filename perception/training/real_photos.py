"""Labelled real photographs for evaluating the wire model beyond synthetic data (2.4.1).

The photos are not committed: Debian packages ship them (wallpaper collections), and
``perception/data/real_wires.json`` holds, per photo, its installed path, package, SHA-256, the
working size and hand-checked wire polylines at that size. Photos without wires are negatives
with wire-like distractors (grass stalks, trunks, plank edges). A label is valid only for the
exact file it was drawn on, hence the checksum.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from perception.params import SyntheticParams
from perception.training.labels import label_mask, rasterise

ANNOTATIONS = Path(__file__).resolve().parents[1] / "data" / "real_wires.json"
DEV_ANNOTATIONS = ANNOTATIONS.with_name("real_dev.json")
"""The development set's additions (issue 20): more negatives from packages no shipped model
trained on; the development set is these plus the test set of ``ANNOTATIONS``."""


@dataclass(frozen=True)
class LabelledPhoto:
    """One annotated photograph: where it is installed, and its wires at `size_px` (H, W)."""

    name: str
    path: Path
    debian_package: str
    sha256: str
    size_px: tuple[int, int]
    description: str
    wires: tuple[tuple[np.ndarray, float], ...]  # ((K, 2) polyline px, width px)


def labelled_photos(path: str | Path = ANNOTATIONS) -> list[LabelledPhoto]:
    """The annotated photographs of an annotation file (default: the committed set)."""
    doc = json.loads(Path(path).read_text())
    return [
        LabelledPhoto(
            name=p["name"],
            path=Path(p["path"]),
            debian_package=p["debian_package"],
            sha256=p["sha256"],
            size_px=(int(p["size_px"][0]), int(p["size_px"][1])),
            description=p["description"],
            wires=tuple(
                (np.asarray(w["points_px"], np.float64), float(w["width_px"])) for w in p["wires"]
            ),
        )
        for p in doc["photos"]
    ]


def wire_mask(photo: LabelledPhoto) -> np.ndarray:
    """(H, W) uint8 {0, 1} label of a photo at its working size: each polyline drawn `width_px`
    wide, labelled as the synthetic wires are (`perception.training.labels.label_mask`)."""
    h, w = photo.size_px
    segments = [np.stack([p[:-1], p[1:]], axis=1) for p, _ in photo.wires]
    if not segments:
        return np.zeros((h, w), np.uint8)
    widths = np.concatenate([np.full(len(p) - 1, width) for p, width in photo.wires])
    segments_px = np.concatenate(segments)
    coverage = rasterise(segments_px, widths, h, w, SyntheticParams().supersampling)
    return label_mask(segments_px, coverage)


def training_exclusions(
    paths: tuple[str | Path, ...] = (ANNOTATIONS, DEV_ANNOTATIONS),
) -> frozenset[str]:
    """SHA-256 digests of photos that must never be training backgrounds: every labelled photo
    (the real-photo test and development sets) and those listed with unlabelled wires."""
    digests: set[str] = set()
    for path in paths:
        doc = json.loads(Path(path).read_text())
        digests |= {p["sha256"] for p in doc["photos"] + doc.get("unlabelled_wires", [])}
    return frozenset(digests)
