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

from pydantic import BaseModel, ConfigDict, Field
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from companion.service_params import ServiceParams
from hil.camera_params import CameraSimParams
from hil.params import VehicleSimParams
from mapping.catenary_params import CatenaryParams
from mapping.params import MappingParams
from perception.params import PerceptionParams
from planning.params import PlanningParams


class LinkParams(BaseModel):
    """The MAVSDK flight link to PX4 (`companion.vehicle_link`)."""

    model_config = ConfigDict(extra="forbid")

    connection_url: str = Field(
        "udpin://0.0.0.0:14540",
        description="MAVSDK connection URL: udpin://HOST:PORT, udpout://HOST:PORT, serial://DEV:BAUD",
    )
    connect_timeout_s: float = Field(
        15.0, gt=0, le=600, description="time to discover the autopilot after connecting, s"
    )
    health_timeout_s: float = Field(
        30.0, gt=0, le=600, description="time for local position, home and pre-arm checks, s"
    )
    telemetry_rate_hz: float = Field(
        30.0, ge=1, le=250, description="rate requested for pose/velocity/attitude streams, Hz"
    )
    setpoint_rate_hz: float = Field(
        20.0, ge=20, le=100, description="rate our setpoints are streamed at (PX4 wants >= 2), Hz"
    )
    setpoint_max_age_s: float = Field(
        0.3,
        gt=0,
        le=2,
        description="planner output older than this trips the watchdog: brake, then Hold, s",
    )
    brake_timeout_s: float = Field(
        2.0, gt=0, le=10, description="longest zero-velocity brake before switching to Hold, s"
    )
    brake_speed_mps: float = Field(
        0.2, gt=0, le=2, description="speed below which braking is done and Hold is requested, m/s"
    )
    offboard_prestream_s: float = Field(
        0.7, ge=0.5, le=2, description="setpoints streamed before requesting offboard, s"
    )
    offboard_confirm_timeout_s: float = Field(
        2.5,
        gt=0,
        le=10,
        description="time for the heartbeat to report OFFBOARD after the request (1 Hz), s",
    )
    offboard_settle_s: float = Field(
        1.2,
        ge=0,
        le=5,
        description="OFFBOARD must still be reported this long after it was confirmed: covers "
        "PX4's end-of-takeoff Hold landing just after the switch (> 1 heartbeat period), s",
    )
    offboard_attempts: int = Field(3, ge=1, le=10, description="offboard entry attempts")
    arm_attempts: int = Field(
        10, ge=1, le=100, description="arming attempts (PX4 denies arming early after boot)"
    )
    arm_confirm_timeout_s: float = Field(
        3.0, gt=0, le=30, description="time for the heartbeat to report armed after an ACK, s"
    )
    arm_retry_interval_s: float = Field(
        1.0, gt=0, le=10, description="pause between denied arming attempts, s"
    )
    takeoff_altitude_m: float = Field(
        3.0, ge=1, le=100, description="takeoff altitude above home, m"
    )
    takeoff_timeout_s: float = Field(
        30.0, gt=0, le=300, description="time to reach takeoff altitude and settle in Hold, s"
    )
    altitude_tolerance_m: float = Field(
        0.5, gt=0, le=5, description="altitude error accepted as 'reached' after takeoff, m"
    )
    land_timeout_s: float = Field(
        60.0, gt=0, le=600, description="time to touch down and disarm after Land, s"
    )
    link_loss_timeout_s: float = Field(
        2.0,
        gt=0,
        le=30,
        description="no telemetry for this long means the link is lost, s",
    )
    reconnect_soft_s: float = Field(
        4.0,
        ge=0,
        le=60,
        description="wait for MAVSDK to recover the link itself before rebuilding it, s",
    )
    reconnect_interval_s: float = Field(
        2.0, gt=0, le=60, description="pause between attempts to rebuild a lost link, s"
    )
    reconnect_max_attempts: int = Field(
        0, ge=0, description="link rebuild attempts before giving up; 0 means never give up"
    )


class Settings(BaseSettings):
    """Every tunable of the product, grouped by the module that uses it."""

    model_config = SettingsConfigDict(
        env_prefix="WIREAVOID_", env_nested_delimiter="__", extra="forbid"
    )

    link: LinkParams = Field(default_factory=LinkParams)
    service: ServiceParams = Field(default_factory=ServiceParams)
    perception: PerceptionParams = Field(default_factory=PerceptionParams)
    mapping: MappingParams = Field(default_factory=MappingParams)
    catenary: CatenaryParams = Field(default_factory=CatenaryParams)
    planning: PlanningParams = Field(default_factory=PlanningParams)
    vehicle_sim: VehicleSimParams = Field(default_factory=VehicleSimParams)
    camera_sim: CameraSimParams = Field(default_factory=CameraSimParams)

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
