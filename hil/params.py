"""Parameters of the SIL vehicle. Composed into `companion.config.Settings`.

Fields that mirror a PX4 parameter carry its name in `json_schema_extra={"px4": NAME}`; the
MAVLink vehicle serves exactly those through the parameter protocol (PARAM_REQUEST_READ /
PARAM_REQUEST_LIST / PARAM_SET), in PX4's own unit (see `px4_parameter_table`). Defaults are
PX4 v1.14 multicopter defaults unless the description says otherwise.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


def _px4(name: str) -> dict[str, str]:
    return {"px4": name}


class VehicleSimParams(BaseModel):
    """The simulated PX4-like multirotor: airframe, cascaded controller, commander, telemetry."""

    model_config = ConfigDict(extra="forbid")

    # --- simulation -------------------------------------------------------------------------
    seed: int = Field(0, description="seed of every random draw (noise, wind, quirks)")
    physics_rate_hz: float = Field(
        250.0, ge=50.0, le=2000.0, description="fixed physics/control step rate, Hz"
    )

    # --- airframe ---------------------------------------------------------------------------
    mass_kg: float = Field(1.5, gt=0.0, le=50.0, description="vehicle mass, kg")
    hover_thrust: float = Field(
        0.5,
        gt=0.1,
        lt=0.9,
        description="normalised collective thrust that hovers; max thrust = m g / hover, 1",
        json_schema_extra=_px4("MPC_THR_HOVER"),
    )
    motor_time_constant_s: float = Field(
        0.03, gt=0.0, le=0.5, description="first-order lag of collective thrust, s"
    )
    drag_coefficient_nspm: float = Field(
        0.15, ge=0.0, le=5.0, description="linear aerodynamic drag on air-relative velocity, N s/m"
    )
    max_angular_accel_radps2: float = Field(
        60.0, gt=0.0, le=500.0, description="bound on roll/pitch/yaw angular acceleration, rad/s^2"
    )

    # --- position / velocity control (PX4 mc_pos_control) -----------------------------------
    xy_pos_p: float = Field(
        0.95,
        gt=0.0,
        le=2.0,
        description="horizontal position P gain, 1/s",
        json_schema_extra=_px4("MPC_XY_P"),
    )
    z_pos_p: float = Field(
        1.0,
        gt=0.0,
        le=1.5,
        description="vertical position P gain, 1/s",
        json_schema_extra=_px4("MPC_Z_P"),
    )
    xy_vel_p: float = Field(
        1.8,
        gt=0.0,
        le=5.0,
        description="horizontal velocity P gain, (m/s^2)/(m/s)",
        json_schema_extra=_px4("MPC_XY_VEL_P_ACC"),
    )
    xy_vel_i: float = Field(
        0.4,
        ge=0.0,
        le=5.0,
        description="horizontal velocity I gain, (m/s^2)/m",
        json_schema_extra=_px4("MPC_XY_VEL_I_ACC"),
    )
    xy_vel_d: float = Field(
        0.2,
        ge=0.0,
        le=2.0,
        description="horizontal velocity D gain, (m/s^2)/(m/s^2)",
        json_schema_extra=_px4("MPC_XY_VEL_D_ACC"),
    )
    z_vel_p: float = Field(
        4.0,
        gt=0.0,
        le=15.0,
        description="vertical velocity P gain, (m/s^2)/(m/s)",
        json_schema_extra=_px4("MPC_Z_VEL_P_ACC"),
    )
    z_vel_i: float = Field(
        2.0,
        ge=0.0,
        le=3.0,
        description="vertical velocity I gain, (m/s^2)/m",
        json_schema_extra=_px4("MPC_Z_VEL_I_ACC"),
    )
    z_vel_d: float = Field(
        0.0,
        ge=0.0,
        le=2.0,
        description="vertical velocity D gain, (m/s^2)/(m/s^2)",
        json_schema_extra=_px4("MPC_Z_VEL_D_ACC"),
    )
    xy_vel_max_mps: float = Field(
        12.0,
        gt=0.0,
        le=20.0,
        description="horizontal velocity limit, m/s",
        json_schema_extra=_px4("MPC_XY_VEL_MAX"),
    )
    xy_cruise_mps: float = Field(
        5.0,
        gt=0.0,
        le=20.0,
        description="horizontal speed of auto modes (RTL), m/s",
        json_schema_extra=_px4("MPC_XY_CRUISE"),
    )
    z_vel_max_up_mps: float = Field(
        3.0,
        gt=0.0,
        le=8.0,
        description="ascent velocity limit, m/s",
        json_schema_extra=_px4("MPC_Z_VEL_MAX_UP"),
    )
    z_vel_max_dn_mps: float = Field(
        1.5,
        gt=0.0,
        le=4.0,
        description="descent velocity limit, m/s",
        json_schema_extra=_px4("MPC_Z_VEL_MAX_DN"),
    )
    acc_hor_mps2: float = Field(
        3.0,
        gt=0.0,
        le=15.0,
        description="horizontal acceleration of auto modes (hold braking, RTL), m/s^2",
        json_schema_extra=_px4("MPC_ACC_HOR"),
    )
    acc_hor_max_mps2: float = Field(
        5.0,
        gt=0.0,
        le=15.0,
        description="slew limit of the horizontal velocity setpoint (offboard too), m/s^2",
        json_schema_extra=_px4("MPC_ACC_HOR_MAX"),
    )
    acc_up_max_mps2: float = Field(
        4.0,
        gt=0.0,
        le=15.0,
        description="slew limit of the upward velocity setpoint, m/s^2",
        json_schema_extra=_px4("MPC_ACC_UP_MAX"),
    )
    acc_down_max_mps2: float = Field(
        3.0,
        gt=0.0,
        le=15.0,
        description="slew limit of the downward velocity setpoint, m/s^2",
        json_schema_extra=_px4("MPC_ACC_DOWN_MAX"),
    )
    tilt_max_air_deg: float = Field(
        45.0,
        gt=1.0,
        le=89.0,
        description="maximum tilt of the thrust vector in flight, deg",
        json_schema_extra=_px4("MPC_TILTMAX_AIR"),
    )
    thr_min: float = Field(
        0.12,
        ge=0.0,
        le=0.5,
        description="minimum normalised collective thrust in flight, 1",
        json_schema_extra=_px4("MPC_THR_MIN"),
    )
    thr_max: float = Field(
        1.0,
        gt=0.5,
        le=1.0,
        description="maximum normalised collective thrust, 1",
        json_schema_extra=_px4("MPC_THR_MAX"),
    )
    takeoff_speed_mps: float = Field(
        1.5,
        gt=0.0,
        le=5.0,
        description="climb speed of auto takeoff, m/s",
        json_schema_extra=_px4("MPC_TKO_SPEED"),
    )
    land_speed_mps: float = Field(
        0.7,
        gt=0.0,
        le=3.0,
        description="descent speed of auto land, m/s",
        json_schema_extra=_px4("MPC_LAND_SPEED"),
    )
    yaw_rate_auto_max_deg_s: float = Field(
        45.0,
        gt=0.0,
        le=360.0,
        description="yaw rate limit of auto modes and yaw setpoints, deg/s",
        json_schema_extra=_px4("MPC_YAWRAUTO_MAX"),
    )

    # --- attitude / rate control (PX4 mc_att_control, mc_rate_control) ---------------------
    roll_p: float = Field(
        6.5,
        gt=0.0,
        le=12.0,
        description="roll attitude P gain, 1/s",
        json_schema_extra=_px4("MC_ROLL_P"),
    )
    pitch_p: float = Field(
        6.5,
        gt=0.0,
        le=12.0,
        description="pitch attitude P gain, 1/s",
        json_schema_extra=_px4("MC_PITCH_P"),
    )
    yaw_p: float = Field(
        2.8,
        gt=0.0,
        le=5.0,
        description="yaw attitude P gain, 1/s",
        json_schema_extra=_px4("MC_YAW_P"),
    )
    rate_p_rp: float = Field(
        25.0,
        gt=0.0,
        le=200.0,
        description="roll/pitch rate loop bandwidth: angular accel per rate error, 1/s "
        "(PX4's MC_ROLLRATE_P is normalised torque, so not mirrored)",
    )
    rate_p_yaw: float = Field(12.0, gt=0.0, le=200.0, description="yaw rate loop bandwidth, 1/s")
    roll_rate_max_deg_s: float = Field(
        220.0,
        gt=0.0,
        le=1800.0,
        description="roll/pitch rate limit, deg/s",
        json_schema_extra=_px4("MC_ROLLRATE_MAX"),
    )
    yaw_rate_max_deg_s: float = Field(
        200.0,
        gt=0.0,
        le=1800.0,
        description="yaw rate limit, deg/s",
        json_schema_extra=_px4("MC_YAWRATE_MAX"),
    )

    # --- commander / navigator --------------------------------------------------------------
    takeoff_alt_m: float = Field(
        2.5,
        ge=0.5,
        le=100.0,
        description="takeoff altitude above home when none is given, m",
        json_schema_extra=_px4("MIS_TAKEOFF_ALT"),
    )
    takeoff_acceptance_m: float = Field(
        0.3,
        gt=0.0,
        le=5.0,
        description="takeoff completes (switch to Hold) within this altitude error, m",
    )
    rtl_return_alt_m: float = Field(
        30.0,
        ge=0.0,
        le=500.0,
        description="RTL climbs to at least this altitude above home (PX4 default 60), m",
        json_schema_extra=_px4("RTL_RETURN_ALT"),
    )
    rtl_land_delay_s: float = Field(
        0.0,
        ge=-1.0,
        le=300.0,
        description="RTL hover time above home before landing, s",
        json_schema_extra=_px4("RTL_LAND_DELAY"),
    )
    nav_acc_rad_m: float = Field(
        2.0,
        gt=0.05,
        le=200.0,
        description="horizontal acceptance radius of auto legs, m",
        json_schema_extra=_px4("NAV_ACC_RAD"),
    )
    offboard_loss_timeout_s: float = Field(
        1.0,
        ge=0.0,
        le=60.0,
        description="no offboard setpoint for this long while in Offboard: failsafe to Hold, s",
        json_schema_extra=_px4("COM_OF_LOSS_T"),
    )
    offboard_entry_max_age_s: float = Field(
        0.5,
        gt=0.0,
        le=5.0,
        description="Offboard is refused unless a setpoint arrived within this age, s "
        "(PX4's offboard_control_mode timeout)",
    )
    companion_loss_timeout_s: float = Field(
        5.0,
        ge=0.0,
        le=60.0,
        description="after a companion heartbeat (MAV_TYPE_ONBOARD_CONTROLLER) was seen, none "
        "for this long while in Offboard: failsafe to Hold, s",
        json_schema_extra=_px4("COM_OBC_LOSS_T"),
    )
    disarm_land_s: float = Field(
        2.0,
        ge=-1.0,
        le=20.0,
        description="auto-disarm this long after landing; negative disables, s",
        json_schema_extra=_px4("COM_DISARM_LAND"),
    )
    disarm_preflight_s: float = Field(
        10.0,
        ge=-1.0,
        le=60.0,
        description="auto-disarm when armed on the ground without takeoff this long; "
        "negative disables, s",
        json_schema_extra=_px4("COM_DISARM_PRFLT"),
    )
    land_detect_time_s: float = Field(
        0.5,
        gt=0.0,
        le=5.0,
        description="ground contact with low thrust this long counts as landed, s",
    )
    health_ok_after_boot_s: float = Field(
        1.0,
        ge=0.0,
        le=60.0,
        description="sensors, EKF position and the pre-arm bit report healthy this long after "
        "boot (simulated estimator convergence), s",
    )
    arm_denied_after_boot_s: float = Field(
        3.0,
        ge=0.0,
        le=60.0,
        description="arming is denied (TEMPORARILY_REJECTED) for this long after boot even when "
        "the pre-arm bit is set: reproduces PX4's 'arming denied right after boot', s",
    )
    takeoff_hold_race_probability: float = Field(
        0.0,
        ge=0.0,
        le=1.0,
        description="probability (seeded) that an Offboard request near the end of a takeoff "
        "loses to the navigator's end-of-takeoff switch to Hold while still ACKed as accepted "
        "(seen in 2 of 11 PX4 SITL runs), 1",
    )
    takeoff_hold_race_window_s: float = Field(
        0.5,
        ge=0.0,
        le=5.0,
        description="an Offboard request within this time before or after takeoff completion "
        "is exposed to the end-of-takeoff Hold race, s",
    )

    # --- world, sensors, battery ------------------------------------------------------------
    home_lat_deg: float = Field(47.397742, ge=-90.0, le=90.0, description="home latitude, deg")
    home_lon_deg: float = Field(8.545594, ge=-180.0, le=180.0, description="home longitude, deg")
    home_alt_amsl_m: float = Field(
        488.0, ge=-500.0, le=9000.0, description="home ground altitude above mean sea level, m"
    )
    wind_ned_mps: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="mean wind velocity, NED, m/s"
    )
    wind_gust_std_mps: float = Field(
        0.0, ge=0.0, le=10.0, description="std of the gust (first-order Gauss-Markov) per axis, m/s"
    )
    wind_gust_time_constant_s: float = Field(
        2.0, gt=0.0, le=60.0, description="correlation time of gusts, s"
    )
    position_noise_std_m: float = Field(
        0.0, ge=0.0, le=5.0, description="white noise on reported position per axis, m"
    )
    velocity_noise_std_mps: float = Field(
        0.0, ge=0.0, le=2.0, description="white noise on reported velocity per axis, m/s"
    )
    attitude_noise_std_rad: float = Field(
        0.0, ge=0.0, le=0.2, description="white noise on reported roll/pitch/yaw, rad"
    )
    battery_cells: int = Field(4, ge=1, le=14, description="series LiPo cells")
    battery_endurance_s: float = Field(
        1200.0, gt=1.0, description="flight time from full to empty at hover thrust, s"
    )

    # --- telemetry stream rates (simulated time; MAV_CMD_SET_MESSAGE_INTERVAL overrides) ---
    heartbeat_rate_hz: float = Field(1.0, gt=0.0, le=50.0, description="HEARTBEAT rate, Hz")
    attitude_rate_hz: float = Field(50.0, gt=0.0, le=250.0, description="ATTITUDE rate, Hz")
    position_rate_hz: float = Field(
        30.0, gt=0.0, le=250.0, description="LOCAL/GLOBAL_POSITION rate, Hz"
    )
    status_rate_hz: float = Field(
        5.0,
        gt=0.0,
        le=50.0,
        description="SYS_STATUS, GPS_RAW_INT, EXTENDED_SYS_STATE rate, Hz",
    )
    slow_rate_hz: float = Field(
        1.0, gt=0.0, le=50.0, description="HOME_POSITION, BATTERY_STATUS rate, Hz"
    )


def px4_parameter_table() -> dict[str, str]:
    """PX4 parameter name -> `VehicleSimParams` field name, for the parameter protocol."""
    table = {}
    for name, field in VehicleSimParams.model_fields.items():
        extra = field.json_schema_extra
        if isinstance(extra, dict) and "px4" in extra:
            table[str(extra["px4"])] = name
    return table
