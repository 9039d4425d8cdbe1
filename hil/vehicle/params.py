"""Parameters of the SIL vehicle. Composed into `companion.cli.settings.SimSettings`.

The defaults are PX4's own: PX4-Autopilot main (March 2026) multicopter defaults with the SIH
quadrotor of airframe 10040 (`sihsim_quadx`), as read from a fresh PX4 SITL over MAVLink. A
field that mirrors a PX4 parameter names it in its description and carries it in
`json_schema_extra={"px4": NAME}`, in PX4's own unit (deg stays deg): the MAVLink vehicle serves
it live under that name (PARAM_REQUEST_READ / _LIST / PARAM_SET), and an airframe or a PX4
parameter file sets it by that name (`hil.vehicle.airframes`). Fields without a PX4 name model
what PX4 does not parameterise (timing quirks, the estimator's error, telemetry rates).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field


def _px4(default: Any, name: str, description: str, **bounds: Any) -> Any:
    """A field mirroring PX4 parameter `name`."""
    return Field(
        default, description=f"{description} ({name})", json_schema_extra={"px4": name}, **bounds
    )


class VehicleSimParams(BaseModel):
    """The simulated PX4 multirotor: SIH airframe, PX4's controllers, commander, estimator error."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    # --- simulation -------------------------------------------------------------------------
    seed: int = Field(0, description="seed of every random draw (wind, estimator error, quirks)")
    physics_rate_hz: float = Field(
        250.0, ge=100.0, le=2000.0, description="fixed physics and control step rate, Hz"
    )

    # --- airframe: PX4's SIH rigid body (simulator_sih) -------------------------------------
    mass_kg: float = _px4(1.0, "SIH_MASS", "vehicle mass, kg", gt=0.0, le=50.0)
    inertia_xx_kgm2: float = _px4(0.025, "SIH_IXX", "roll inertia, kg m^2", gt=0.0, le=10.0)
    inertia_yy_kgm2: float = _px4(0.025, "SIH_IYY", "pitch inertia, kg m^2", gt=0.0, le=10.0)
    inertia_zz_kgm2: float = _px4(0.03, "SIH_IZZ", "yaw inertia, kg m^2", gt=0.0, le=10.0)
    rotor_thrust_max_n: float = _px4(
        5.0, "SIH_T_MAX", "thrust of one of the 4 rotors at full command, N", gt=0.0, le=500.0
    )
    rotor_torque_max_nm: float = _px4(
        0.1, "SIH_Q_MAX", "reaction torque of one rotor at full command, N m", gt=0.0, le=50.0
    )
    roll_arm_m: float = _px4(0.2, "SIH_L_ROLL", "rotor arm about the roll axis, m", gt=0.0, le=5.0)
    pitch_arm_m: float = _px4(
        0.2, "SIH_L_PITCH", "rotor arm about the pitch axis, m", gt=0.0, le=5.0
    )
    drag_coefficient_nspm: float = _px4(
        1.0,
        "SIH_KDV",
        "linear drag on the air-relative velocity, N s/m (SIH's strong 1.0; a real 1-2 kg "
        "quadrotor is nearer 0.1-0.3)",
        ge=0.0,
        le=20.0,
    )
    angular_drag_nmsprad: float = _px4(
        0.025, "SIH_KDW", "angular damping, N m s/rad", ge=0.0, le=5.0
    )
    motor_time_constant_s: float = _px4(
        0.05, "SIH_T_TAU", "first-order lag of each rotor's command, s", gt=0.0, le=0.5
    )
    hover_thrust: float = _px4(
        0.5,
        "MPC_THR_HOVER",
        "normalised collective thrust the position controller assumes hovers, 1",
        gt=0.1,
        lt=0.9,
    )

    # --- position and velocity control (mc_pos_control) -------------------------------------
    xy_pos_p: float = _px4(0.95, "MPC_XY_P", "horizontal position P gain, 1/s", gt=0.0, le=2.0)
    z_pos_p: float = _px4(1.0, "MPC_Z_P", "vertical position P gain, 1/s", gt=0.0, le=1.5)
    xy_vel_p: float = _px4(
        1.8, "MPC_XY_VEL_P_ACC", "horizontal velocity P gain, 1/s", gt=0.0, le=5.0
    )
    xy_vel_i: float = _px4(
        0.4, "MPC_XY_VEL_I_ACC", "horizontal velocity I gain, 1/s^2", ge=0.0, le=60.0
    )
    xy_vel_d: float = _px4(0.2, "MPC_XY_VEL_D_ACC", "horizontal velocity D gain, 1", ge=0.0, le=2.0)
    z_vel_p: float = _px4(4.0, "MPC_Z_VEL_P_ACC", "vertical velocity P gain, 1/s", gt=0.0, le=15.0)
    z_vel_i: float = _px4(2.0, "MPC_Z_VEL_I_ACC", "vertical velocity I gain, 1/s^2", ge=0.0, le=3.0)
    z_vel_d: float = _px4(0.0, "MPC_Z_VEL_D_ACC", "vertical velocity D gain, 1", ge=0.0, le=2.0)
    vel_deriv_cutoff_hz: float = _px4(
        5.0, "MPC_VELD_LP", "low-pass cutoff of the velocity derivative (D term), Hz", gt=0.0
    )
    xy_vel_max_mps: float = _px4(
        12.0, "MPC_XY_VEL_MAX", "horizontal velocity limit (offboard too), m/s", gt=0.0, le=20.0
    )
    xy_cruise_mps: float = _px4(
        5.0, "MPC_XY_CRUISE", "horizontal speed of auto modes (Hold, RTL), m/s", gt=0.0, le=20.0
    )
    z_vel_max_up_mps: float = _px4(
        3.0, "MPC_Z_VEL_MAX_UP", "ascent velocity limit, m/s", gt=0.0, le=8.0
    )
    z_vel_max_dn_mps: float = _px4(
        1.5, "MPC_Z_VEL_MAX_DN", "descent velocity limit, m/s", gt=0.0, le=4.0
    )
    z_vel_auto_up_mps: float = _px4(
        3.0, "MPC_Z_V_AUTO_UP", "ascent speed of auto modes (RTL climb), m/s", gt=0.0, le=8.0
    )
    z_vel_auto_dn_mps: float = _px4(
        1.5, "MPC_Z_V_AUTO_DN", "descent speed of auto modes above MPC_LAND_ALT1, m/s", gt=0.0
    )
    acc_hor_mps2: float = _px4(
        3.0, "MPC_ACC_HOR", "horizontal acceleration of auto modes, m/s^2", gt=0.0, le=15.0
    )
    acc_hor_max_mps2: float = _px4(
        5.0, "MPC_ACC_HOR_MAX", "horizontal acceleration limit of manual modes, m/s^2", gt=0.0
    )
    acc_up_max_mps2: float = _px4(
        4.0, "MPC_ACC_UP_MAX", "upward acceleration of auto modes, m/s^2", gt=0.0, le=15.0
    )
    acc_down_max_mps2: float = _px4(
        3.0, "MPC_ACC_DOWN_MAX", "downward acceleration of auto modes, m/s^2", gt=0.0, le=15.0
    )
    jerk_auto_mps3: float = _px4(
        4.0, "MPC_JERK_AUTO", "jerk limit of auto-mode trajectories, m/s^3", gt=0.0, le=80.0
    )
    tilt_max_air_deg: float = _px4(
        45.0, "MPC_TILTMAX_AIR", "maximum tilt in flight, deg", gt=1.0, le=89.0
    )
    tilt_max_land_deg: float = _px4(
        12.0, "MPC_TILTMAX_LND", "maximum tilt while taking off and landing, deg", gt=1.0, le=89.0
    )
    thr_min: float = _px4(
        0.12, "MPC_THR_MIN", "minimum collective thrust in flight, 1", ge=0.0, le=0.5
    )
    thr_max: float = _px4(1.0, "MPC_THR_MAX", "maximum collective thrust, 1", gt=0.5, le=1.0)
    thr_xy_margin: float = _px4(
        0.3, "MPC_THR_XY_MARG", "thrust kept for horizontal control at saturation, 1", ge=0.0
    )
    takeoff_speed_mps: float = _px4(
        1.5, "MPC_TKO_SPEED", "climb speed of takeoff, m/s", gt=0.0, le=5.0
    )
    takeoff_ramp_s: float = _px4(
        3.0, "MPC_TKO_RAMP_T", "takeoff ramp of the climb-speed limit from idle thrust, s", ge=0.0
    )
    spoolup_s: float = _px4(
        1.0, "COM_SPOOLUP_TIME", "motor spool-up after arming before takeoff, s", ge=0.0, le=5.0
    )
    land_speed_mps: float = _px4(
        0.7, "MPC_LAND_SPEED", "descent speed of Land below MPC_LAND_ALT2, m/s", gt=0.0, le=3.0
    )
    land_alt1_m: float = _px4(
        10.0, "MPC_LAND_ALT1", "above this Land descends at MPC_Z_V_AUTO_DN, m", ge=0.0
    )
    land_alt2_m: float = _px4(
        5.0, "MPC_LAND_ALT2", "below this Land descends at MPC_LAND_SPEED, m", ge=0.0
    )
    land_alt3_m: float = _px4(
        1.0, "MPC_LAND_ALT3", "below this Land crawls at MPC_LAND_CRWL (distance sensor), m"
    )
    land_crawl_mps: float = _px4(
        0.3, "MPC_LAND_CRWL", "descent speed of the last metre of Land, m/s", gt=0.0, le=2.0
    )
    yaw_rate_auto_max_deg_s: float = _px4(
        60.0, "MPC_YAWRAUTO_MAX", "yaw rate limit of auto modes, deg/s", gt=0.0, le=360.0
    )

    # --- attitude control (mc_att_control) -------------------------------------------------
    roll_p: float = _px4(4.0, "MC_ROLL_P", "roll attitude P gain, 1/s", gt=0.0, le=12.0)
    pitch_p: float = _px4(4.0, "MC_PITCH_P", "pitch attitude P gain, 1/s", gt=0.0, le=12.0)
    yaw_p: float = _px4(2.8, "MC_YAW_P", "yaw attitude P gain, 1/s", gt=0.0, le=5.0)
    yaw_weight: float = _px4(
        0.4, "MC_YAW_WEIGHT", "yaw priority against roll and pitch, 1", ge=0.0, le=1.0
    )
    roll_rate_max_deg_s: float = _px4(
        220.0, "MC_ROLLRATE_MAX", "roll rate limit, deg/s", gt=0.0, le=1800.0
    )
    pitch_rate_max_deg_s: float = _px4(
        220.0, "MC_PITCHRATE_MAX", "pitch rate limit, deg/s", gt=0.0, le=1800.0
    )
    yaw_rate_max_deg_s: float = _px4(
        200.0, "MC_YAWRATE_MAX", "yaw rate limit, deg/s", gt=0.0, le=1800.0
    )

    # --- rate control (mc_rate_control): torques normalised to the mixer's range ------------
    roll_rate_p: float = _px4(0.15, "MC_ROLLRATE_P", "roll rate P gain, 1/(rad/s)", ge=0.0)
    roll_rate_i: float = _px4(0.2, "MC_ROLLRATE_I", "roll rate I gain, 1/rad", ge=0.0)
    roll_rate_d: float = _px4(0.003, "MC_ROLLRATE_D", "roll rate D gain, 1/(rad/s^2)", ge=0.0)
    roll_rate_k: float = _px4(1.0, "MC_ROLLRATE_K", "roll rate gain scale, 1", gt=0.0, le=5.0)
    roll_rate_int_lim: float = _px4(
        0.3, "MC_RR_INT_LIM", "roll rate integrator limit, 1", ge=0.0, le=1.0
    )
    pitch_rate_p: float = _px4(0.15, "MC_PITCHRATE_P", "pitch rate P gain, 1/(rad/s)", ge=0.0)
    pitch_rate_i: float = _px4(0.2, "MC_PITCHRATE_I", "pitch rate I gain, 1/rad", ge=0.0)
    pitch_rate_d: float = _px4(0.003, "MC_PITCHRATE_D", "pitch rate D gain, 1/(rad/s^2)", ge=0.0)
    pitch_rate_k: float = _px4(1.0, "MC_PITCHRATE_K", "pitch rate gain scale, 1", gt=0.0, le=5.0)
    pitch_rate_int_lim: float = _px4(
        0.3, "MC_PR_INT_LIM", "pitch rate integrator limit, 1", ge=0.0, le=1.0
    )
    yaw_rate_p: float = _px4(0.2, "MC_YAWRATE_P", "yaw rate P gain, 1/(rad/s)", ge=0.0)
    yaw_rate_i: float = _px4(0.1, "MC_YAWRATE_I", "yaw rate I gain, 1/rad", ge=0.0)
    yaw_rate_d: float = _px4(0.0, "MC_YAWRATE_D", "yaw rate D gain, 1/(rad/s^2)", ge=0.0)
    yaw_rate_k: float = _px4(1.0, "MC_YAWRATE_K", "yaw rate gain scale, 1", gt=0.0, le=5.0)
    yaw_rate_int_lim: float = _px4(
        0.3, "MC_YR_INT_LIM", "yaw rate integrator limit, 1", ge=0.0, le=1.0
    )
    yaw_torque_cutoff_hz: float = _px4(
        2.0, "MC_YAW_TQ_CUTOFF", "low-pass cutoff of the yaw torque command, Hz", ge=0.0
    )
    dgyro_cutoff_hz: float = _px4(
        20.0, "IMU_DGYRO_CUTOFF", "low-pass cutoff of the angular acceleration (D term), Hz", gt=0
    )

    # --- commander / navigator --------------------------------------------------------------
    takeoff_alt_m: float = _px4(
        2.5, "MIS_TAKEOFF_ALT", "takeoff height above home when none is given, m", ge=0.5, le=100
    )
    nav_mc_alt_rad_m: float = _px4(
        0.8, "NAV_MC_ALT_RAD", "altitude acceptance of takeoff and RTL climb, m", gt=0.05, le=200
    )
    nav_acc_rad_m: float = _px4(
        2.0, "NAV_ACC_RAD", "horizontal acceptance radius of auto legs, m", gt=0.05, le=200.0
    )
    rtl_return_alt_m: float = _px4(
        30.0, "RTL_RETURN_ALT", "RTL climbs to this height above home (far from home), m", ge=0
    )
    rtl_descend_alt_m: float = _px4(
        10.0, "RTL_DESCEND_ALT", "RTL descends to this height above home before landing, m", ge=0
    )
    rtl_land_delay_s: float = _px4(
        0.0, "RTL_LAND_DELAY", "RTL hover at RTL_DESCEND_ALT before landing (-1: never), s", ge=-1
    )
    rtl_min_dist_m: float = _px4(
        10.0,
        "RTL_MIN_DIST",
        "within this distance of home RTL climbs only to its cone (RTL_CONE_ANG), m",
        ge=0.0,
    )
    rtl_cone_ang_deg: int = _px4(
        45, "RTL_CONE_ANG", "half angle of the RTL return-altitude cone (0: none), deg", ge=0, le=90
    )
    offboard_loss_timeout_s: float = _px4(
        1.0, "COM_OF_LOSS_T", "no offboard setpoint for this long in Offboard: failsafe, s", ge=0
    )
    offboard_loss_action: int = _px4(
        0,
        "COM_OBL_RC_ACT",
        "offboard-loss action: 0 Position, 1 Altitude, 2 Manual (without RC: Return), 3 Return, "
        "4 Land, 5 Hold, 6 Terminate, 7 Disarm",
        ge=0,
        le=7,
    )
    offboard_entry_max_age_s: float = Field(
        0.5,
        gt=0.0,
        le=5.0,
        description="Offboard is refused unless a setpoint arrived within this age, s "
        "(PX4's offboard_control_mode timeout)",
    )
    companion_loss_timeout_s: float = _px4(
        5.0,
        "COM_OBC_LOSS_T",
        "after a companion heartbeat was seen, none for this long in Offboard: a warning "
        "(PX4 takes no action; the offboard loss does), s",
        ge=0.0,
        le=60.0,
    )
    disarm_land_s: float = _px4(
        2.0, "COM_DISARM_LAND", "auto-disarm this long after landing (negative: never), s", ge=-1
    )
    disarm_preflight_s: float = _px4(
        10.0,
        "COM_DISARM_PRFLT",
        "auto-disarm when armed on the ground without takeoff this long (negative: never), s",
        ge=-1.0,
    )
    land_detect_z_vel_max_mps: float = _px4(
        0.25, "LNDMC_Z_VEL_MAX", "land detector: vertical speed below this is still, m/s", gt=0
    )
    land_detect_xy_vel_max_mps: float = _px4(
        1.5, "LNDMC_XY_VEL_MAX", "land detector: horizontal speed below this is still, m/s", gt=0
    )
    land_detect_rot_max_deg_s: float = _px4(
        20.0, "LNDMC_ROT_MAX", "land detector: rotation below this is still, deg/s", gt=0.0
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

    # --- estimator error (EKF2 estimate against truth; 0 = a perfect estimate) --------------
    ekf_velocity_error_std_mps: float = Field(
        0.0,
        ge=0.0,
        le=2.0,
        description="std of the estimate's horizontal velocity error per axis (vertical: half); "
        "the horizontal position error is its integral, pulled back by GPS, m/s",
    )
    ekf_velocity_error_time_constant_s: float = Field(
        2.5, gt=0.0, le=600.0, description="correlation time of the velocity error, s"
    )
    ekf_gps_correction_time_constant_s: float = Field(
        2.0,
        gt=0.0,
        le=600.0,
        description="time constant GPS pulls the horizontal position error back with, s",
    )
    ekf_altitude_error_std_m: float = Field(
        0.0, ge=0.0, le=10.0, description="std of the estimate's altitude error (baro drift), m"
    )
    ekf_altitude_error_time_constant_s: float = Field(
        4.0, gt=0.0, le=600.0, description="correlation time of the altitude error, s"
    )
    ekf_heading_error_std_deg: float = Field(
        0.0, ge=0.0, le=90.0, description="std of the estimate's heading error, deg"
    )
    ekf_heading_error_time_constant_s: float = Field(
        10.0, gt=0.0, le=600.0, description="correlation time of the heading error, s"
    )

    # --- world, battery ----------------------------------------------------------------------
    home_lat_deg: float = _px4(47.397743, "SIH_LOC_LAT0", "home latitude, deg", ge=-90.0, le=90.0)
    home_lon_deg: float = _px4(8.545594, "SIH_LOC_LON0", "home longitude, deg", ge=-180.0, le=180.0)
    home_alt_amsl_m: float = _px4(
        489.4, "SIH_LOC_H0", "home ground altitude above mean sea level, m", ge=-500.0, le=9000.0
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
    battery_cells: int = _px4(4, "BAT1_N_CELLS", "series LiPo cells", ge=1, le=14)
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
    display_rate_hz: float = Field(
        10.0,
        gt=0.0,
        le=100.0,
        description="what a ground station displays: ALTITUDE, VFR_HUD, ATTITUDE_TARGET, "
        "POSITION_TARGET_LOCAL_NED, HIGHRES_IMU, ODOMETRY rate, Hz",
    )
    slow_rate_hz: float = Field(
        1.0,
        gt=0.0,
        le=50.0,
        description="HOME_POSITION, BATTERY_STATUS, ESTIMATOR_STATUS, SYSTEM_TIME, CURRENT_MODE, "
        "PING, CURRENT_EVENT_SEQUENCE rate, Hz",
    )


def px4_parameter_table() -> dict[str, str]:
    """PX4 parameter name -> `VehicleSimParams` field name, for the fields PX4 names."""
    table = {}
    for name, field in VehicleSimParams.model_fields.items():
        extra = field.json_schema_extra
        if isinstance(extra, dict) and "px4" in extra:
            table[str(extra["px4"])] = name
    return table
