"""The MAVSDK flight link to PX4: telemetry, commands, offboard, setpoint streaming, watchdog."""
