"""The one typed configuration of wireavoid: TOML file plus `WIREAVOID_*` environment overrides.

Each core owns the model of its own tunables (`perception.params`, `mapping.droan.params`,
`mapping.catenary.params`, `planning.params`) so that it stays importable without `companion`;
this module composes them, with the link's and the service's, into the flight process'
`Settings` tree, the only place defaults live. The commands extend it with the simulator's
sections (`companion.cli.settings.SimSettings`); the flight process never sees those.
Environment variables override the file: `WIREAVOID_MAPPING__ROBOT_RADIUS_M=0.4`.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from pydantic import Field
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from companion.flight.params import FlightParams
from companion.ground.params import GeofenceParams, GroundParams
from companion.ingest.params import CameraParams
from companion.link.params import LinkParams
from companion.mission import MissionParams
from companion.record.params import RecordParams
from companion.service_params import ServiceParams
from mapping.catenary.params import CatenaryParams
from mapping.droan.params import MappingParams
from perception.params import PerceptionParams
from planning.params import PlanningParams


class Settings(BaseSettings):
    """Every tunable of the product, grouped by the module that uses it."""

    model_config = SettingsConfigDict(
        env_prefix="WIREAVOID_", env_nested_delimiter="__", extra="forbid"
    )

    link: LinkParams = Field(default_factory=LinkParams)
    service: ServiceParams = Field(default_factory=ServiceParams)
    mission: MissionParams = Field(default_factory=MissionParams)
    flight: FlightParams = Field(default_factory=FlightParams)
    camera: CameraParams = Field(default_factory=CameraParams)
    perception: PerceptionParams = Field(default_factory=PerceptionParams)
    mapping: MappingParams = Field(default_factory=MappingParams)
    catenary: CatenaryParams = Field(default_factory=CatenaryParams)
    planning: PlanningParams = Field(default_factory=PlanningParams)
    ground: GroundParams = Field(default_factory=GroundParams)
    geofence: GeofenceParams = Field(default_factory=GeofenceParams)
    record: RecordParams = Field(default_factory=RecordParams)

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        """Environment first, then the TOML values passed in by `load_settings`, then defaults."""
        return env_settings, init_settings


def load_settings(path: Path | None = None, model: type[Settings] = Settings) -> Settings:
    """Settings of type `model` from the TOML file at `path` (defaults when None) with
    environment overrides.

    Raises `pydantic.ValidationError` naming the offending key on an unknown key or a value
    out of bounds, and `FileNotFoundError` when `path` does not exist.
    """
    values: dict[str, Any] = {}
    if path is not None:
        with Path(path).open("rb") as f:
            values = tomllib.load(f)
    return model(**values)
