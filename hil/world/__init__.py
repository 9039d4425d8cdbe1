"""The simulated 3D world: ground, obstacles and wires."""
