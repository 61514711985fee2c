"""Identification of the dynamics parameters (paper Section 3 and 4.1-4.2).

Sobol sensitivity of the 28 parameters on the responses of Eqs. 22-25 (``responses``, ``sensitivity``,
``sensitivity_report``), the drive log and the synthetic experiment (``drive_log``, ``experiment``), and the
calibration itself: Eq. 28 (``problem``), its optimisers (``aco``, ``solvers``), intervals (``uncertainty``)
and the run that writes Table 4 and Figure 5 (``run``).
"""
