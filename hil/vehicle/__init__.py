"""The PX4-like multirotor on simulated time: rigid body, cascaded controller, commander modes."""
