"""Folders of labelled images: what `wireavoid evaluate` scores and `wireavoid train --frames`
mixes into its synthetic batches.

A folder holds images with PNG wire masks (nonzero = wire), in either layout:

- `DIR/images/NAME.EXT` with `DIR/masks/NAME.png` (also `NAME_mask.png` there), or
- `DIR/NAME.EXT` with `DIR/NAME_mask.png` side by side,

where EXT is one of jpg, jpeg, png, bmp, tif, tiff, webp. Images without a mask are
reported and skipped.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
OUTPUT_TAGS = ("_mask", "_prob", "_overlay")
"""Stem endings of masks and of `detect`'s own outputs: never treated as input images."""


def image_files(path: Path) -> list[Path]:
    """Input images: `path` itself, or the images directly in the folder `path`, sorted.

    Files whose stem ends in _mask, _prob or _overlay are left out.
    """
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise FileNotFoundError(f"{path} is neither an image file nor a folder")
    return sorted(
        p
        for p in path.iterdir()
        if p.suffix.lower() in IMAGE_SUFFIXES and not p.stem.endswith(OUTPUT_TAGS)
    )


def image_mask_pairs(folder: Path) -> tuple[list[tuple[Path, Path]], list[Path]]:
    """((image, mask) pairs, images without a mask) of a dataset folder (module doc layouts)."""
    if (folder / "images").is_dir():
        image_dir, mask_dirs = folder / "images", [folder / "masks", folder / "images"]
    else:
        image_dir, mask_dirs = folder, [folder]
    pairs, unmatched = [], []
    for image in image_files(image_dir):
        candidates = [d / f"{image.stem}{tag}.png" for d in mask_dirs for tag in ("", "_mask")]
        mask = next((c for c in candidates if c.is_file() and c != image), None)
        if mask is None:
            unmatched.append(image)
        else:
            pairs.append((image, mask))
    return pairs, unmatched


def read_image(path: Path) -> np.ndarray:
    """(H, W, 3) uint8 BGR image; ValueError naming the file when it cannot be decoded."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError(f"cannot read image {path}")
    return image


def read_mask(path: Path) -> np.ndarray:
    """(H, W) bool wire mask of a PNG (any nonzero value is wire)."""
    mask = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if mask is None:
        raise ValueError(f"cannot read mask {path}")
    return (mask if mask.ndim == 2 else mask.max(axis=2)) > 0


class LabelledFrames:
    """The labelled images of some folders, held in memory, served as training crops."""

    def __init__(self, folders: list[str] | tuple[str, ...]) -> None:
        images, masks = [], []
        for folder in folders:
            pairs, _ = image_mask_pairs(Path(folder))
            if not pairs:
                raise ValueError(f"no image/mask pairs in {folder}")
            for image_path, mask_path in pairs:
                image, mask = read_image(image_path), read_mask(mask_path)
                if image.shape[:2] != mask.shape:
                    raise ValueError(f"{image_path} and {mask_path} differ in size")
                images.append(image[..., ::-1])
                masks.append(mask.astype(np.uint8))
        self.images, self.masks = images, masks

    def __len__(self) -> int:
        return len(self.images)

    def crop(
        self, rng: np.random.Generator, height_px: int, width_px: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """A drawn frame's RGB uint8 (H, W, 3) crop and its uint8 {0, 1} mask, mirrored left
        to right half the time; frames smaller than the crop are resized up first."""
        k = int(rng.integers(len(self)))
        image, mask = self.images[k], self.masks[k]
        h, w = mask.shape
        scale = max(height_px / h, width_px / w, 1.0)
        if scale > 1.0:
            size = (int(np.ceil(w * scale)), int(np.ceil(h * scale)))
            image = cv2.resize(image, size, interpolation=cv2.INTER_LINEAR)
            mask = cv2.resize(mask, size, interpolation=cv2.INTER_NEAREST)
            h, w = mask.shape
        top = int(rng.integers(h - height_px + 1))
        left = int(rng.integers(w - width_px + 1))
        image = image[top : top + height_px, left : left + width_px]
        mask = mask[top : top + height_px, left : left + width_px]
        if rng.random() < 0.5:
            image, mask = image[:, ::-1], mask[:, ::-1]
        return np.ascontiguousarray(image), np.ascontiguousarray(mask)
