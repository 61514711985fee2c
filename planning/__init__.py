"""Time-optimal stroke planning with toppra (issue: planning)."""
