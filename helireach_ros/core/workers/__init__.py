"""Worker processes: the solver pool and the planner node's solver back-end."""
