"""Tunables of the MAVSDK flight link to PX4 (`companion.link.vehicle_link`)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class LinkParams(BaseModel):
    """The MAVSDK flight link to PX4 (`companion.link.vehicle_link`)."""

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
    call_drain_timeout_s: float = Field(
        5.0,
        gt=0,
        le=60,
        description="before MAVSDK is destroyed (close, rebuild), wait this long for its calls "
        "still running in worker threads to return (companion.link.calls), s",
    )
    reconnect_max_attempts: int = Field(
        0, ge=0, description="link rebuild attempts before giving up; 0 means never give up"
    )
    failsafe_check: Literal["off", "warn", "refuse"] = Field(
        "warn",
        description="before offboard, read PX4's failsafe parameters (COM_OBL_RC_ACT, "
        "COM_OF_LOSS_T, RTL_RETURN_ALT, NAV_RCL_ACT) and warn, or refuse to start offboard, "
        "where a failsafe would climb or fly home blind through wires (companion.link.preflight)",
    )
