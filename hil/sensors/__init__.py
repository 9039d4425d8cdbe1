"""Simulated cameras rendering the world from the vehicle's true pose."""
