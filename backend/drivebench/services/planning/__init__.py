"""Planned networks and the network planner."""
