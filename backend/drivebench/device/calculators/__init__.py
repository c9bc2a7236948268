"""Network calculators: DIP switches, COB-IDs, cable length, the planner's devices."""
