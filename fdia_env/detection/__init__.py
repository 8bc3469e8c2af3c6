"""Detection numerics shared by the detection game and its baselines (MATH.md §3)."""
