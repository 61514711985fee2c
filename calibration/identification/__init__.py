"""Calibration of the key parameters against drive logs (Sections 3.4, 4.1-4.2).

* ``settings``: the job's [calibration] table; ``problem``: Eq. 28 as plain data and a vectorised objective;
  ``joint``: several logs in one objective; ``peak``: the measured peak of Eq. 23.
* ``aco``, ``polish``, ``solvers``: the paper's ant colony, its local polish, DE and least squares behind one result type.
* ``bootstrap``, ``uncertainty``: 95 % intervals (parametric bootstrap; the Jacobian second opinion).
* ``adequacy``: the lack-of-fit verdict and score tests; ``recording``: the channel delay and encoder offset.
* ``inputs``: the calibration's inputs read and checked once (parameter names, channel map, the logs' rows).
* ``run``: the fit: Eq. 28 solved, intervals, verdict, validation, as a ``Calibration``; ``record`` its calibrated.json,
  ``report`` its Table 4 files, ``figure`` its Figure 5, ``console`` its lines; ``methods`` the optimisers' names.
"""
