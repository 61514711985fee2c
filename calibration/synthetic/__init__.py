"""SYNTHETIC drive logs, labelled as such with their seed and truth (``servo-press experiment``).

* ``experiment``: one servo-cushion log from the model with a chosen truth, noise and die-contact ringing, and the
  cushion's force as its own channel logs it (``process_force_N``).
* ``effects``: effects a real log carries and the model lacks (delay, offset, load-dependent efficiency, losses, AR(1), ripple).
* ``fleet``: a fleet of dated logs of one press whose truth drifts (``experiment --fleet``).
"""
