"""Which drive logs are the same recording: by their samples as read, whatever the file, its name or its format.

Two logs are compared sample by sample (:attr:`calibration.traces.drive_log.DriveLog.samples`: time s, crank angle deg, motor
speed rpm, torque N m, after the reader's repairs): a sample of one is *shared* with the other when the other holds a
sample identical in time and in every value, within ``[identity] sample_match_relative`` of drive_log.toml times each
column's range (far below any drive's noise, far above the rounding of a CSV or of a unit conversion; the crank
angle compared modulo 360 deg, as an encoder may wrap it or not). So a byte copy under another name, the same samples
through another format (the TDMS of a Scope export, a CSV written from it) and the log less a few rows are the same
recording; two recordings of the same motion are not, their noise differs (a lone sample whose noise agrees by
chance is not counted: a shared stretch of a recording matches sample after sample).

* :func:`refuse_duplicates`: logs fitted jointly (several ``--log``) of which one shares more than
  ``same_recording_share`` of its samples with another are refused: fitted twice, one recording counts as two and
  the intervals shrink with nothing learnt.
* :func:`validation_share`: the share of the ``--validate`` log's samples that were fitted; above
  ``same_recording_share`` it is refused (the validation would be no out-of-sample check), any share above 0 is
  returned for the caller to state beside the validation figures.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from press_io.errors import PressDataError

from calibration.traces.drive_log import DriveLog, _settings


def shared_share(a: np.ndarray, b: np.ndarray, relative: float) -> float:
    """The share (0 to 1) of the samples (rows) of ``a`` that ``b`` holds too, identical in time and values within
    ``relative`` times each column's range in ``a`` (the angle, column 1, modulo 360 deg), counting only samples whose
    neighbour in ``a`` is shared too. Both in time order."""
    if a is None or b is None or len(a) == 0 or len(b) == 0:
        return 0.0
    span = np.ptp(a, axis=0)
    span[1] = min(span[1], 360.0)
    tol = relative * np.where(span > 0.0, span, np.abs(a).max(axis=0) + 1.0)
    j = np.clip(np.searchsorted(b[:, 0], a[:, 0]), 1, len(b) - 1) if len(b) > 1 else np.zeros(len(a), dtype=int)
    hit = np.zeros(len(a), dtype=bool)
    for k in ((j - 1, j) if len(b) > 1 else (j,)):  # the neighbours in time: b's sample before and after
        d = np.abs(a - b[k])
        d[:, 1] = np.abs((a[:, 1] - b[k, 1] + 180.0) % 360.0 - 180.0)
        hit |= np.all(d <= tol, axis=1)
    # a shared stretch of a recording matches sample after sample; a lone match is chance (two recordings' torque
    # noise agrees within the tolerance about once in 10^4 samples where the angle and speed carry no noise)
    run = hit & (np.concatenate(([False], hit[:-1])) | np.concatenate((hit[1:], [False])))
    return float(np.mean(run))


def refuse_duplicates(logs: Sequence[DriveLog], settings=None) -> None:
    """Refuse (:class:`PressDataError` naming both) two logs of ``logs`` that are one recording: either shares more
    than ``same_recording_share`` of its samples with the other."""
    cfg = _settings(settings)
    for i, a in enumerate(logs):
        for b in logs[i + 1:]:
            share = max(shared_share(a.samples, b.samples, cfg.sample_match_relative),
                        shared_share(b.samples, a.samples, cfg.sample_match_relative))
            if share > cfg.same_recording_share:
                raise PressDataError("--log", "--log", b.source, f"is the recording of --log {a.source} ({100.0 * share:.4g} % of the "
                                     f"samples of one are in the other, identical in time and values; over "
                                     f"{100.0 * cfg.same_recording_share:g} %, drive_log.toml [identity]): fitted twice, one recording "
                                     "would count as two and the intervals shrink with nothing learnt; give each recording once")


def validation_share(fitted: Sequence[DriveLog], validation: DriveLog, settings=None) -> float:
    """The share (0 to 1) of the validation log's samples that a fitted log holds too; above ``same_recording_share``
    refused (:class:`PressDataError` naming both): a validation on the fitted samples is no out-of-sample check."""
    cfg = _settings(settings)
    best, which = 0.0, None
    for lg in fitted:
        share = shared_share(validation.samples, lg.samples, cfg.sample_match_relative)
        if share > best:
            best, which = share, lg
    if best > cfg.same_recording_share:
        raise PressDataError("--validate", "--validate", validation.source, f"holds the samples of the fitted log {which.source} "
                             f"({100.0 * best:.4g} % of its samples are fitted ones, identical in time and values; over "
                             f"{100.0 * cfg.same_recording_share:g} %, drive_log.toml [identity]): a validation predicts a "
                             "recording the fit did not see; give another recording (another day or motion)")
    return best


def check(fitted: Sequence[DriveLog], validation: DriveLog | None, settings=None) -> float:
    """:func:`refuse_duplicates` on the fitted logs, then :func:`validation_share` of ``validation`` (0 without one)."""
    refuse_duplicates(fitted, settings)
    return validation_share(fitted, validation, settings) if validation is not None else 0.0


def validation_warning(share: float) -> tuple[str, ...]:
    """The warning for a validation log that shares ``share`` (0 to 1, below the refusal) of its samples with the
    fitted logs; none for 0."""
    if share <= 0.0:
        return ()
    return (f"the validation log shares {100.0 * share:.3g} % of its samples with the fitted logs (identical in time and "
            "values: part of the same recording): its figures are not wholly out of sample",)
