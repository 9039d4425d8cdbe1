"""Parameters of the SIL vehicle and world. Composed into `companion.config.Settings`."""

from pydantic import BaseModel, Field


class VehicleSimParams(BaseModel):
    """The simulated PX4-like multirotor."""

    seed: int = Field(0, description="seed of every random draw (noise, wind)")
