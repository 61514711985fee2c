"""Calibration of the key parameters against drive logs (Sections 3.4, 4.1-4.2).

* ``settings``: the job's [calibration] table; ``problem``: Eq. 28 as plain data and a vectorised objective;
  ``joint``: several logs in one objective; ``peak``: the measured peak of Eq. 23.
* ``aco``, ``polish``, ``solvers``: the paper's ant colony, its local polish, DE and least squares behind one result type.
* ``bootstrap``, ``uncertainty``: 95 % intervals (parametric bootstrap; the Jacobian second opinion).
* ``adequacy``: the lack-of-fit verdict and score tests; ``recording``: the channel delay and encoder offset.
* ``run``: the ``calibrate`` run: fit, intervals, verdict, validation, calibrated.json, Table 4 and Figure 5.
"""
