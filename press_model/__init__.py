"""servo-press-twin: press and job data, the closed-loop linkage model and its dynamics (paper Section 2).

It imports neither ``calibration`` nor ``planning`` nor the command line (``servo_press``); its plumbing
(errors, result files, interrupts, workers) is ``press_io``.
"""

__version__ = "0.1.0"
