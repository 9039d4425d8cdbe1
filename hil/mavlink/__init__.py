"""The simulated vehicle on the wire: MAVLink 2 over UDP like PX4 SITL."""
