"""The camera frame the flight process consumes, and the protocol every camera source follows.

One rig: a stereo camera giving disparity and a colour camera registered to its reference
(left) camera, as an OAK-D's depth-aligned colour stream is. The colour image may be an
integer down-scale of the disparity image (same optics, fewer pixels), so the wire mask of the
CNN lands on the disparity camera's pixels by pooling alone (`mapping.droan.expansion`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


class CameraError(RuntimeError):
    """The camera cannot deliver frames; the message says why (dead device, end of file)."""


@dataclass(frozen=True, slots=True)
class CameraFrame:
    """One exposure of the rig, stamped at mid-exposure on the process clock.

    stamp_s: exposure time, s (the clock of `companion.clock.Clock`; the source converts).
    sequence: the source's frame counter (gaps = frames the source dropped).
    image_bgr: `(h, w, 3) uint8` colour image registered to the stereo reference camera, or
        None when this exposure has none (a disparity-only frame).
    disparity_px: `(H, W) float32` disparity of the reference camera, px (NaN = invalid,
        0 = no return, > 0 = a return; thesis 4.4.2), or None for a colour-only frame.
    """

    stamp_s: float
    sequence: int
    image_bgr: np.ndarray | None
    disparity_px: np.ndarray | None

    def __post_init__(self) -> None:
        if self.image_bgr is None and self.disparity_px is None:
            raise ValueError("a camera frame needs a colour image, a disparity image or both")
        if self.image_bgr is not None and (
            self.image_bgr.ndim != 3 or self.image_bgr.shape[2] != 3
        ):
            raise ValueError(f"colour image must be (h, w, 3), got {self.image_bgr.shape}")
        if self.disparity_px is not None and self.disparity_px.ndim != 2:
            raise ValueError(f"disparity must be (H, W), got {self.disparity_px.shape}")


class CameraSource(Protocol):
    """A source of `CameraFrame`s: the OAK-D, a recorded flight, a simulator.

    `open()` connects (all I/O happens there, never in the constructor); `next_frame()` waits
    for the next frame and raises `CameraError` when the source is dead or exhausted;
    `close()` releases it and is idempotent.
    """

    async def open(self) -> None: ...

    async def next_frame(self) -> CameraFrame: ...

    async def close(self) -> None: ...
