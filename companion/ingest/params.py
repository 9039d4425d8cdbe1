"""Tunables of the camera ingest (`companion.ingest`), composed into `Settings.camera`."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class CameraParams(BaseModel):
    """The camera rig the flight process reads: which source, its rate and image sizes.

    The rig's geometry (size, intrinsics, baseline, mount) is `[mapping] camera_*`; the colour
    image is that camera pooled by `colour_downscale` (the wire CNN's input size).
    """

    model_config = ConfigDict(extra="forbid")

    source: Literal["oakd", "none"] = Field(
        "oakd",
        description="where frames come from in `wireavoid run`: an OAK-D (depthai), or none "
        "(no frames: perception stays stale and the mission never flies blind); simulated "
        "flights and replays plug in their own source",
    )
    frame_rate_hz: float = Field(
        10.0, gt=0.0, le=60.0, description="exposures per second, colour and stereo (4.6.1), Hz"
    )
    colour_downscale: int = Field(
        2,
        ge=1,
        le=8,
        description="the colour image is the rig's reference camera pooled by this integer "
        "factor (640x480 -> 320x240, the CNN's input), registered as an OAK-D's depth-aligned "
        "colour",
    )
    mono_width_px: int = Field(640, ge=16, description="OAK-D stereo pair's image width, px")
    mono_height_px: int = Field(400, ge=16, description="OAK-D stereo pair's image height, px")
    sync_threshold_s: float = Field(
        0.02,
        gt=0.0,
        le=1.0,
        description="OAK-D: colour and depth exposures farther apart than this are not paired, s",
    )
    oakd_device: str = Field(
        "", description="OAK-D to open (its MXID, or an IP for PoE models); empty: the first found"
    )
