"""Tunables of the companion service process (`companion.service`, `wireavoid run`).

A module of its own, importing nothing of `companion`, so that `companion.config` can compose
it into `Settings` without an import cycle (`companion.service` imports the link, which imports
`companion.config`).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class ServiceParams(BaseModel):
    """The companion service process (`companion.service`, `wireavoid run`)."""

    model_config = ConfigDict(extra="forbid")

    tick_rate_hz: float = Field(
        2.0,
        ge=0.2,
        le=50.0,
        description="rate of the supervision loop; each on-time tick updates the systemd STATUS "
        "and feeds the systemd watchdog (keep 1/rate well under WatchdogSec / 2), Hz",
    )
    status_period_s: float = Field(
        10.0,
        gt=0.0,
        le=3600.0,
        description="a status line is logged this often, and at once when the link state, "
        "flight mode, armed, landed state or readiness changes, s",
    )
    watchdog_max_lag_s: float = Field(
        1.0,
        gt=0.0,
        le=60.0,
        description="a tick starting later than this does not feed the systemd watchdog, s",
    )
    connect_retry_interval_s: float = Field(
        2.0,
        gt=0.0,
        le=60.0,
        description="pause between attempts to find the autopilot at start-up "
        "(each attempt waits link.connect_timeout_s), s",
    )
    stop_timeout_s: float = Field(
        5.0,
        gt=0.0,
        le=120.0,
        description="on SIGTERM, time for the flight process to finish its current work "
        "before it is cancelled, s",
    )
    startup_grace_s: float = Field(
        10.0,
        gt=0.0,
        le=600.0,
        description="start-up time asked of systemd beyond each connect attempt and its pause "
        "(EXTEND_TIMEOUT_USEC), s",
    )
