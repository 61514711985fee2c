"""Identification of the dynamics parameters (paper Sections 3 and 4.1-4.2), grouped by topic in the data flow's order.

* ``responses``: the four responses of Eqs. 22-25 (RMSE, peak ratio, torque level, work), shared by the topics below.
* ``sensitivity``: the Sobol analysis of the 28 parameters and the ``sensitivity`` command's files (Section 3).
* ``traces``: drive logs and drive traces (TwinCAT Scope, TDMS, CSV) read through a channel map onto the crank grid.
* ``synthetic``: SYNTHETIC drive logs and fleets made from the model with a stated truth and seed.
* ``identification``: Eq. 28 and its solvers (the paper's ant colony, DE, least squares), intervals, the adequacy
  verdict, the recording's delay and offset, and the ``calibrate`` run.
* ``design``: the D-optimal design of calibration runs within the motor's limits (``design-experiment``; the command
  itself and the runs' playback sit in the command layer and in planning, which this package does not import).
* ``fleet``: fleet monitoring, one calibration per log on Dask workers, its rules and its files (``monitor``).
"""
