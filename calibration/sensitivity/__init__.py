"""Sobol sensitivity of the 28 parameters (Section 3).

* ``sobol``: the problem as plain data, then sampling, evaluation (the batch model) and analysis (SALib).
* ``report``: the ``sensitivity`` command's load cases, its files (indices, key parameters, Figure 3) and convergence.
"""
