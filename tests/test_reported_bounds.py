"""What the ringing and recording fits may report: nothing the log cannot carry.

A die-contact ringing fit that ends on the edge of what the crank grid resolves (at its Nyquist rate, or decaying within
one grid step) is refused as a result (calibration/identification/peak.py ``Ringing.unresolved``), and a delay, offset
or lost motion whose interval holds zero is printed as none beyond the noise, not as a value
(calibration/identification/recording.py ``RecordingEstimate.statement``). The values are the worked example's on an
edited press before its held parameters were freed (docs/validation.md): 24.45 Hz and 20.5 ms on a grid with 20.5 ms
between points, a delay of -5.50 ms in -14.46 .. 3.45 ms."""
from __future__ import annotations

import numpy as np
import pytest

from calibration.identification.peak import Ringing
from calibration.identification.recording import RecordingEstimate

STEP = 0.0205  # s between grid points after die contact
SPAN = 17 * STEP  # the region's length


def ringing(frequency_Hz: float, decay_s: float) -> Ringing:
    return Ringing(np.arange(18), np.zeros(18), np.zeros((18, 18)), frequency_Hz, decay_s, 61100.0, STEP, SPAN)


@pytest.mark.parametrize("frequency_Hz, decay_s, edge", [
    (0.5 / STEP, STEP, "at the grid's Nyquist rate and decaying within one grid step"),
    (0.5 / STEP, 0.030, "at the grid's Nyquist rate"),
    (13.1, STEP, "decaying within one grid step"),
    (1.0 / SPAN, 0.030, "one cycle over its region"),
    (13.1, SPAN, "never decaying over its region"),
])
def test_a_ringing_fit_on_the_edge_of_what_the_grid_resolves_is_refused(frequency_Hz, decay_s, edge):
    why = ringing(frequency_Hz, decay_s).unresolved()
    assert why.startswith("die-contact ringing not removed") and f"({edge};" in why, why
    assert "61100" not in why  # the refused fit's amplitude is no result


def test_a_ringing_the_grid_resolves_is_kept():
    # the same log before its recording was "corrected": 13.1 Hz, decay 32 ms, well inside the grid's resolution
    assert ringing(13.1, 0.0316).unresolved() == ""
    assert Ringing(np.arange(3), np.zeros(3), np.zeros((3, 3)), 80.0, 1e-4, 1.0).unresolved() == ""  # no grid stated


def estimate(delay_s, delay_iv, offset_deg, offset_iv, corrected=True):
    sd = ((delay_iv[1] - delay_iv[0]) / 3.92, (offset_iv[1] - offset_iv[0]) / 3.92)
    return RecordingEstimate(delay_s, offset_deg, sd, (delay_iv[0], offset_iv[0]), (delay_iv[1], offset_iv[1]), -0.95, False,
                             1, 0.95, 0.9, corrected=corrected)


def test_a_delay_whose_interval_holds_zero_is_not_printed_as_a_value():
    line = estimate(-0.0055, (-0.01446, 0.00345), 0.299, (-0.442, 1.041)).statement()
    assert "-5.50" not in line and "+0.299" not in line
    assert "no torque-channel delay beyond its noise (95 % interval -14.46 .. 3.45 ms)" in line
    assert "no encoder offset beyond its noise" in line


def test_a_delay_beyond_its_noise_is_printed_with_its_interval():
    line = estimate(0.002, (0.0012, 0.0028), 0.01, (-0.1, 0.12)).statement()
    assert "a torque-channel delay of 2.00 ms (95 % interval 1.20 .. 2.80 ms)" in line
    assert "no encoder offset beyond its noise" in line
