"""Tunables of the trajectory-library planner (thesis 4.5), composed into `Settings`."""

from enum import StrEnum

from pydantic import BaseModel, ConfigDict, Field, model_validator


class UnknownPolicy(StrEnum):
    """How the planner treats map points no observation has seen (unknown is not free)."""

    FREE = "free"  # unseen counts as free (the thesis' implicit choice; optimistic)
    COLLISION = "collision"  # unseen counts as occupied everywhere on the checked segment
    COST = "cost"  # unseen within the braking distance is a collision, beyond it a cost


class YawPolicy(StrEnum):
    """Where the vehicle's nose points while it tracks a trajectory."""

    MOTION = "motion"  # face the direction of the commanded horizontal velocity
    GOAL = "goal"  # face the goal
    FIXED = "fixed"  # hold `fixed_yaw_rad`


class SetpointMode(StrEnum):
    """What the tracker sends the autopilot while it follows a plan."""

    TRAJECTORY = "trajectory"  # reference position + velocity feed-forward
    VELOCITY = "velocity"  # velocity with the tracker's own position correction


class CheckMode(StrEnum):
    """How trajectories are batched into occupancy queries (eq. 4.5 per waypoint)."""

    ALL = "all"  # one query for every waypoint of every trajectory
    CHUNKED = "chunked"  # cost-ordered chunks of `check_chunk_size` trajectories, one query each


class PlanningParams(BaseModel):
    """Planner parameters; each field names its unit and thesis reference."""

    model_config = ConfigDict(extra="forbid")

    # --- vehicle limits the library is built from (4.5, Fig. 4.8) ---
    max_speed_mps: float = Field(
        2.0, gt=0, le=15, description="cruise speed (4.6.2 flew 2 m/s), m/s"
    )
    max_accel_mps2: float = Field(
        2.0, gt=0, le=20, description="largest acceleration per axis of the library, m/s^2"
    )
    max_jerk_mps3: float = Field(
        4.0, gt=0, le=100, description="largest jerk of the library (lateral: v * yaw accel), m/s^3"
    )
    max_yaw_rate_radps: float = Field(
        0.8, gt=0, le=6.3, description="largest yaw rate of turns and of the tracker, rad/s"
    )
    max_vertical_speed_mps: float = Field(
        1.0, gt=0, le=5, description="fastest climb/descent of the library, m/s"
    )
    # --- library shape (Fig. 4.8) ---
    horizon_s: float = Field(4.0, gt=0.5, le=20, description="duration of each trajectory, s")
    waypoints: int = Field(
        20, ge=4, le=200, description="m, waypoints each trajectory is sampled into (eq. 4.7)"
    )
    turn_levels: int = Field(
        3, ge=0, le=12, description="turn curvatures per side (left and right), count"
    )
    max_heading_change_rad: float = Field(
        1.4, gt=0, le=3.1, description="heading change of the sharpest turn over the horizon, rad"
    )
    climb_levels: int = Field(
        2, ge=0, le=8, description="climb rates per direction (climb and descend), count"
    )
    speed_levels: int = Field(
        2, ge=1, le=5, description="target speeds, evenly spaced in (0, max_speed_mps], count"
    )
    speed_bins: int = Field(
        9,
        ge=2,
        le=41,
        description="initial speeds in [0, max_speed_mps] a library is built at, count",
    )
    integration_substeps: int = Field(
        8, ge=1, le=50, description="integration steps between two waypoints, count"
    )
    # --- selection (eq. 4.7, 4.8) ---
    alpha: float = Field(
        0.5, ge=0, le=1, description="alpha, distance vs heading weight of eq. 4.7/4.8"
    )
    distance_scale_m: float = Field(
        1.0, gt=0, le=100, description="distance that weighs like 1 rad of heading (eq. 4.8), m"
    )
    descent_cost_per_m: float = Field(
        0.3,
        ge=0,
        le=10,
        description=(
            "cost per m of net descent below the start and the goal, so wires are passed "
            "over rather than under (sag; thesis 4.7.2 run 10 failed going under) while a "
            "goal below is descended to, 1/m"
        ),
    )
    switch_cost: float = Field(
        1.0,
        ge=0,
        le=10,
        description=(
            "hysteresis: cost per (max speed x horizon) of mean waypoint distance between a "
            "trajectory and last cycle's choice"
        ),
    )
    unknown_policy: UnknownPolicy = Field(
        UnknownPolicy.COST, description="unseen map points: free, collision, or cost (4.4.5)"
    )
    unknown_cost: float = Field(
        2.0, ge=0, le=100, description="cost of a fully unseen checked segment (policy 'cost')"
    )
    safety_margin_m: float = Field(
        0.5,
        ge=0,
        le=10,
        description="free path required beyond the pruned end plus braking distance, m",
    )
    own_volume_m: float = Field(
        0.5,
        ge=0,
        le=5,
        description="the first this much of every trajectory lies inside the vehicle itself: "
        "unseen there is not unknown (no camera sees that close); keep it at the robot radius, m",
    )
    min_altitude_m: float = Field(
        1.0, ge=0, le=100, description="flight floor above home (NED z = 0); lower is collision, m"
    )
    max_altitude_m: float = Field(
        120.0,
        gt=0,
        le=10000,
        description="flight ceiling above home (NED z = 0); higher is collision (above it "
        "already: no higher than now); the flight process flies under the lower of this and "
        "geofence.max_altitude_m, m",
    )
    min_track_s: float = Field(
        1.5,
        ge=0,
        le=20,
        description="a chosen trajectory is followed at least this long even if pruned earlier, s",
    )
    check_mode: CheckMode = Field(CheckMode.ALL, description="batching of collision queries")
    check_chunk_size: int = Field(
        16, ge=1, le=1000, description="trajectories per query in 'chunked' mode, count"
    )
    # --- receding horizon and recovery (4.5) ---
    rate_hz: float = Field(10.0, ge=10, le=100, description="receding-horizon replanning rate, Hz")
    hover_speed_mps: float = Field(
        0.25, gt=0, le=2, description="speed under which the vehicle counts as stopped, m/s"
    )
    align_heading_rad: float = Field(
        1.2,
        gt=0,
        le=3.2,
        description="when stopped and the goal is further off the nose, rotate to it first, rad",
    )
    recovery_yaw_rate_radps: float = Field(
        0.6, gt=0, le=3, description="yaw rate of the rotate-in-place recovery (4.5), rad/s"
    )
    recovery_max_turn_rad: float = Field(
        6.3, gt=0, le=20, description="rotation without finding a way before rewinding, rad"
    )
    stuck_timeout_s: float = Field(
        8.0, gt=0, le=120, description="no progress to the goal for this long means stuck, s"
    )
    progress_min_m: float = Field(
        0.5, gt=0, le=20, description="distance-to-goal gain that counts as progress, m"
    )
    breadcrumb_spacing_m: float = Field(
        0.5, gt=0, le=10, description="spacing of the recorded flown path (rewind), m"
    )
    breadcrumb_max: int = Field(400, ge=10, le=10000, description="flown-path points kept, count")
    rewind_distance_m: float = Field(
        4.0, gt=0, le=100, description="how far back along the flown path a rewind goes, m"
    )
    rewind_speed_mps: float = Field(0.8, gt=0, le=5, description="speed of a rewind, m/s")
    rewind_climb_m: float = Field(
        1.0,
        ge=0,
        le=10,
        description="height a rewind gains (first, third... rewind) or loses (second...) along "
        "its length where the map has seen that space free, so the camera sees the obstacle "
        "from another altitude: a wire level with the camera, on the horizon, is the one the "
        "CNN misses; 0: rewinds keep the flown path's heights, m",
    )
    max_rewinds: int = Field(
        3, ge=0, le=50, description="rewinds without progress before the goal is unreachable"
    )
    # --- goals ---
    arrival_tolerance_m: float = Field(
        0.5, gt=0, le=20, description="distance to the goal that counts as arrived, m"
    )
    approach_distance_m: float = Field(
        3.0,
        ge=0,
        le=50,
        description="within this horizontal distance of the goal (at any height above or "
        "below it), a straight segment to it, free and seen up to arrival_tolerance_m from it, "
        "is flown instead of the library (beyond 4.5: the library cannot settle on a goal, nor "
        "reach one above or below the camera's view), m",
    )
    approach_speed_mps: float = Field(
        1.0, gt=0, le=10, description="speed of the final straight approach to the goal, m/s"
    )
    unreachable_confirm_cycles: int = Field(
        5, ge=1, le=100, description="cycles the goal must be seen in solid collision, count"
    )
    goal_blocked_timeout_s: float = Field(
        10.0,
        ge=0,
        le=600,
        description="a goal seen in solid collision is held short of and re-checked every "
        "cycle for this long: seen free for unreachable_confirm_cycles again, the vehicle flies "
        "on (one view's false obstacle ends no mission); still blocked, the goal is "
        "unreachable, s",
    )
    unreachable_range_m: float = Field(
        6.0,
        gt=0,
        le=1000,
        description="the goal counts as seen in solid collision (`OccupancyQuery.solid`: never "
        "the wire depth prior, 4.4.3) only from this close, where stereo depth is fine, m",
    )
    stop_path_max_gap_m: float = Field(
        1.0,
        ge=0,
        le=10,
        description="a brake follows the path last checked free (its braking distance "
        "included) when the vehicle is within this of it, else the library's stop trajectory "
        "from where the vehicle is, m",
    )
    # --- path tracking ---
    setpoint_mode: SetpointMode = Field(
        SetpointMode.TRAJECTORY,
        description="how the tracker flies a plan: 'trajectory' sends the reference position "
        "with its velocity as feed-forward (the autopilot's position loop corrects its lag), "
        "'velocity' sends velocities with the tracker's own position correction",
    )
    position_gain_per_s: float = Field(
        1.0, ge=0, le=10, description="velocity correction per m of position error, 1/s"
    )
    max_correction_mps: float = Field(
        1.0, ge=0, le=10, description="largest position-error velocity correction, m/s"
    )
    velocity_lead_s: float = Field(
        0.2,
        ge=0,
        le=2,
        description="feed-forward: the velocity setpoint is the reference's this far ahead, s",
    )
    blend_time_s: float = Field(
        0.5, ge=0, le=5, description="time a new trajectory's start offset fades out over, s"
    )
    setpoint_accel_slack: float = Field(
        1.5, ge=1, le=10, description="setpoint velocity change limit, in units of max accel"
    )
    yaw_policy: YawPolicy = Field(YawPolicy.MOTION, description="where the nose points")
    fixed_yaw_rad: float = Field(0.0, ge=-3.1416, le=3.1416, description="yaw of policy 'fixed'")
    yaw_motion_min_speed_mps: float = Field(
        0.5, gt=0, le=5, description="below this speed policy 'motion' holds the yaw, m/s"
    )
    setpoint_rate_hz: float = Field(
        20.0, ge=20, le=200, description="tracker setpoint rate (flight link), Hz"
    )

    @model_validator(mode="after")
    def _consistent(self) -> "PlanningParams":
        if self.hover_speed_mps >= self.max_speed_mps:
            raise ValueError("hover_speed_mps must be below max_speed_mps")
        return self

    @property
    def library_size(self) -> int:
        """Trajectories in one speed bin: turns x climbs x speeds, plus the stop."""
        return (2 * self.turn_levels + 1) * (2 * self.climb_levels + 1) * self.speed_levels + 1
