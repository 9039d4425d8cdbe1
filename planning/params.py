"""Tunables of the trajectory-library planner (thesis 4.5), composed into `Settings`."""

from pydantic import BaseModel, Field


class PlanningParams(BaseModel):
    """Planner parameters; each field names its unit and thesis reference."""

    alpha: float = Field(
        0.5, ge=0, le=1, description="alpha, distance vs heading weight of eq. 4.7/4.8"
    )
    max_speed_mps: float = Field(2.0, gt=0, description="cruise speed (4.6.2 flew 2 m/s), m/s")
    rate_hz: float = Field(10.0, gt=0, description="receding-horizon replanning rate, Hz")
