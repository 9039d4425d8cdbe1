"""Shared geometry beneath every package: frames, rotations, poses, cameras, shapes.

Imports nothing of wireavoid's own; every other package may import it."""
