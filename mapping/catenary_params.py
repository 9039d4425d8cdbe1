"""Tunables of multi-view catenary reconstruction (thesis ch. 3). Composed into `Settings`."""

from pydantic import BaseModel, Field


class CatenaryParams(BaseModel):
    """Catenary fitting parameters; each field names its unit and thesis reference."""

    points_per_curve: int = Field(100, ge=4, description="M, samples along the catenary (3.3.2)")
