"""Parameter calibration against measured motor torque (issue: calibration)."""
