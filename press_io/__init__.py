"""The plumbing every layer shares: errors and one-line messages, atomic result files and the run records
beside them, interrupts (SIGINT/SIGTERM), forked worker processes and progress lines.

It imports nothing of the project: the model, calibration, planning and the command line all stand on it.
"""
