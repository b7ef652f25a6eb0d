"""Landing plans: the planner (solve, replay, verdict), its figure, and the fallback without a solve."""
