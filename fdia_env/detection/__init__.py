"""Detection numerics shared by the detection game and its baselines (docs/math.md §3)."""
