"""Software-in-the-loop harness: a PX4-like vehicle over real MAVLink, simulated cameras."""
