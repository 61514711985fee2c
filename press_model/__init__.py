"""servo-press-twin: press data, the closed-loop linkage model and its dynamics."""

__version__ = "0.1.0"
