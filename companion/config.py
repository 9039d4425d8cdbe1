"""The one typed configuration of wireavoid: TOML file plus `WIREAVOID_*` environment overrides.

Each core owns the model of its own tunables (`mapping.params`, `planning.params`,
`perception.params`, `hil.params`) so that it stays importable without `companion`;
this module composes them into one `Settings` tree, the only place defaults live.
Environment variables override the file: `WIREAVOID_MAPPING__ROBOT_RADIUS_M=0.4`.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from pydantic import BaseModel, Field
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from hil.params import VehicleSimParams
from mapping.catenary_params import CatenaryParams
from mapping.params import MappingParams
from perception.params import PerceptionParams
from planning.params import PlanningParams


class LinkParams(BaseModel):
    """The MAVSDK flight link to PX4."""

    connection_url: str = Field(
        "udpin://0.0.0.0:14540",
        description="MAVSDK connection URL: udpin://HOST:PORT, udpout://HOST:PORT, serial://DEV:BAUD",
    )


class Settings(BaseSettings):
    """Every tunable of the product, grouped by the module that uses it."""

    model_config = SettingsConfigDict(
        env_prefix="WIREAVOID_", env_nested_delimiter="__", extra="forbid"
    )

    link: LinkParams = Field(default_factory=LinkParams)
    perception: PerceptionParams = Field(default_factory=PerceptionParams)
    mapping: MappingParams = Field(default_factory=MappingParams)
    catenary: CatenaryParams = Field(default_factory=CatenaryParams)
    planning: PlanningParams = Field(default_factory=PlanningParams)
    vehicle_sim: VehicleSimParams = Field(default_factory=VehicleSimParams)

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


def load_settings(path: Path | None = None) -> Settings:
    """Settings from the TOML file at `path` (defaults when None) with environment overrides.

    Raises `pydantic.ValidationError` naming the offending key on an unknown key or a value
    out of bounds, and `FileNotFoundError` when `path` does not exist.
    """
    values: dict[str, Any] = {}
    if path is not None:
        with Path(path).open("rb") as f:
            values = tomllib.load(f)
    return Settings(**values)
