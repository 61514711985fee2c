"""Designing the calibration experiment (``design-experiment``): runs that identify the parameters best.

* ``run_family``: the batch model of any run of one press at the cost of a few array sums.
* ``information``: what a run can tell (information matrix with the recording's nuisance) and the predicted intervals.
* ``noise``: the noise level the intervals are predicted for (the job's keys or a first calibration's calibrated.json).
* ``runs``: the runs' parametrisation, the motor's limits on each, and the D-optimal exchange search.
* ``report``: the design as files (run_N/job.toml, profile.csv, cam_table.csv, prediction.json, report.md).
"""
