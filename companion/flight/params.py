"""Tunables of the closed loop (`companion.flight.process`), composed into `Settings.flight`."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class FlightParams(BaseModel):
    """The closed loop: staleness limits, loop rates and reporting."""

    model_config = ConfigDict(extra="forbid")

    perception_max_age_s: float = Field(
        0.5,
        gt=0.0,
        le=5.0,
        description="the newest frame fused into the map may be this old; older, perception is "
        "stale and the vehicle brakes and holds (thesis 4.4: the map needs fresh frames), s",
    )
    planner_max_age_s: float = Field(
        0.4,
        gt=0.0,
        le=5.0,
        description="a plan older than this is stale: the tracker sends an invalid brake, which "
        "the link turns into brake-then-Hold (the link's own limit on setpoints stays), s",
    )
    pose_jump_m: float = Field(
        1.0,
        gt=0.0,
        le=100.0,
        description="a local position this far from where the previous one predicts it (at its "
        "velocity) is an estimator reset: the map, built in the old frame, is rebuilt and the "
        "vehicle holds until it is fresh again, m",
    )
    pose_jump_hold_s: float = Field(
        1.0,
        ge=0.0,
        le=30.0,
        description="after a jump of the local position, perception counts as stale (the "
        "vehicle brakes and holds) for at least this long while the map is rebuilt from new "
        "frames, s",
    )
    pose_jump_max_gap_s: float = Field(
        0.5,
        gt=0.0,
        le=10.0,
        description="positions further apart than this are not checked for a jump (after a gap "
        "the vehicle may have flown anywhere), s",
    )
    wires_during_takeoff_and_landing: bool = Field(
        True,
        description="fuse the wire masks of frames taken while the mission is not airborne (on "
        "the ground, arming, the autopilot's takeoff climb, landing); off, those frames give "
        "the map their stereo only. The climb sweeps the camera through the height of every "
        "wire in view, and the wire prior of views a few decimetres apart (4-20 m along each "
        "ray, C-space expanded, 4.4.3) overlaps into a fan between the climb and the wire that "
        "no-wire votes cannot carve (4.4.5): the ladder wire's fan walled off 1.1-3.7 m up, "
        "3.5-9 m ahead. On: the climb also sees a wire just above the flight altitude against "
        "the sky (the ladder-wire world: 43-47 s flights with it, 85-110 s without)",
    )
    camera_timeout_s: float = Field(
        2.0,
        gt=0.0,
        le=60.0,
        description="no frame from the camera for this long is reported as a dead camera, s",
    )
    camera_retry_s: float = Field(
        1.0, gt=0.0, le=60.0, description="pause before reopening a camera that failed, s"
    )
    mission_rate_hz: float = Field(
        10.0, ge=1.0, le=50.0, description="rate the mission manager is stepped at, Hz"
    )
    status_period_s: float = Field(
        5.0,
        gt=0.0,
        le=3600.0,
        description="the stage timings (p50/p99 latency, dropped frames) are logged this often, s",
    )
    timing_window: int = Field(
        2000, ge=10, le=1_000_000, description="latency samples per stage kept for p50/p99"
    )
