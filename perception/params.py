"""Tunables of wire segmentation (thesis ch. 2, 4.4.1), composed into `Settings`."""

from pydantic import BaseModel, Field


class PerceptionParams(BaseModel):
    """Wire-segmentation parameters; each field names its unit and thesis reference."""

    model: str = Field(
        "k32-k32-d1-d2-d4-d8-d16-d1-k2", description="architecture name of the zoo (2.3.1)"
    )
    confidence_threshold: float = Field(
        0.95, gt=0, lt=1, description="wire-probability threshold of the mask (4.4.1)"
    )
