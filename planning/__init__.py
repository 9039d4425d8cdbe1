"""Trajectory-library planning and path tracking (thesis 4.5): pure, synchronous."""
