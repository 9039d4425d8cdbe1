"""Tunables of the flight recorder (`companion.record.writer`), composed into `Settings.record`."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class RecordParams(BaseModel):
    """Recording a flight to MCAP: file rotation, the size cap on the drone, compression."""

    model_config = ConfigDict(extra="forbid")

    path: str = Field(
        "",
        description="record every flight of the process to this MCAP file (strftime fields "
        "are filled in at start, e.g. /var/log/wireavoid/flight-%Y%m%d-%H%M%S.mcap); empty: "
        "no recording (`--record FILE` sets it)",
    )
    split_size_mb: float = Field(
        512.0,
        gt=0.0,
        le=100_000.0,
        description="a recording file that reaches this size is closed and the next part "
        "opened (FILE, FILE-001.mcap, ...; each part opens on its own in Foxglove), MB",
    )
    max_total_mb: float = Field(
        8192.0,
        gt=0.0,
        le=10_000_000.0,
        description="the parts of one recording together stay under this: the oldest parts "
        "are deleted first (the drone keeps the newest minutes), MB",
    )
    compression: Literal["zstd", "lz4", "none"] = Field(
        "zstd", description="MCAP chunk compression (images are PNG/JPEG inside already)"
    )
    chunk_size_kb: int = Field(
        1024, ge=16, le=65_536, description="MCAP chunk size before compression, KB"
    )
    queue_messages: int = Field(
        512,
        ge=8,
        le=100_000,
        description="bus messages waiting for the writer thread; beyond, messages are dropped "
        "and counted (the recorder never stalls the flight)",
    )
    timing_period_s: float = Field(
        1.0, gt=0.0, le=3600.0, description="the stage timings are recorded this often, s"
    )
    disparity_preview: bool = Field(
        True,
        description="also record a colour-mapped JPEG of each disparity image at half size "
        "(`/camera/disparity_preview`, for Foxglove's image panel); the lossless disparity is "
        "always recorded",
    )
