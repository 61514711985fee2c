"""Time-optimal stroke planning with toppra (paper Section 4.3): path dynamics, constraint objects,
the planner, the cam profile, forward-dynamics playback and the theoretical-vs-calibrated comparison."""
