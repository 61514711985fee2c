"""servo-press-twin: press and job data, the closed-loop linkage model and its dynamics (paper Section 2).

Nothing in this package outside :mod:`press_model.commands` imports ``calibration`` or ``planning``.
"""

__version__ = "0.1.0"
