"""The inputs of a calibration, each read and validated once where it enters: the parameters to calibrate, the channel
map of ``--log-format`` and the drive logs (their rows, gridded later once per recording correction without reading
the file again). The fit (:mod:`calibration.identification.run`) takes the objects these return, never the paths.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from press_io.errors import PressDataError, ServoPressError, one_line
from press_model.jobs import Job
from press_model.press_data import PressData
from press_model.readers import is_file, read_text_file

from calibration.traces.channel_map import ChannelMap, load_channel_map
from calibration.traces.drive_log import LogRows, read_log_rows
from calibration.identification.problem import NO_PARAMETERS
from calibration.identification.settings import CalibrationSettings
from calibration.traces.trace_log import read_trace_rows


@dataclass(frozen=True)
class LogFormat:
    """How a run's drive logs are read (``--torque-unit``, ``--log-format``): plain drive-log CSVs with their torque in
    ``torque_unit``, or drive traces through the channel map file ``channel_map``, which gives each channel's unit."""

    torque_unit: str = "N*m"
    channel_map: str | None = None

    def read_map(self, press: PressData) -> ChannelMap | None:
        """The channel map read and checked against ``press`` (:func:`channel_map_for`), or None for plain CSVs."""
        return channel_map_for(Path(self.channel_map) if self.channel_map is not None else None, self.torque_unit, press)


@dataclass(frozen=True)
class FitChoice:
    """What the user chose for a calibration (``--method``, ``--parameters``, ``--seed``): the method (None: the job's
    default_method; "all": every method, where the command compares them), the parameters (a comma list or a
    key_parameters.json, :func:`calibration_parameters`; None: the job's list) and the optimisers' seed."""

    method: str | None = None
    parameters: str | None = None
    seed: int = 0


def key_parameters(arg: str | None, default: tuple[str, ...]) -> tuple[str, ...]:
    """Parameter names from a key_parameters.json of ``servo-press sensitivity``, a comma list, or the job's default."""
    if arg is None:
        return default
    path = Path(arg)
    if path.suffix == ".json" or is_file(path):
        if not is_file(path):
            raise PressDataError("--parameters", "--parameters", arg, "must be an existing key_parameters.json or a comma-separated list of names")
        try:
            obj = json.loads(read_text_file(path, "--parameters"))
        except json.JSONDecodeError as exc:
            raise PressDataError(str(path), "<json>", exc.msg, "is not valid JSON") from None
        names = obj.get("key_parameters") if isinstance(obj, dict) else None
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise PressDataError(str(path), "key_parameters", names, "must be a list of names (the file `servo-press sensitivity` writes)")
        return _once(tuple(names), str(path), "key_parameters")
    return _once(tuple(n.strip() for n in arg.split(",") if n.strip()), "--parameters", "--parameters")


def _once(names: tuple[str, ...], source: str, field: str) -> tuple[str, ...]:
    """``names`` when none is repeated; a repeated name is refused where the user wrote it (not the job file)."""
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise PressDataError(source, field, list(names), f"names {', '.join(twice)} twice: give each parameter once")
    return names


def calibration_parameters(arg: str | None, press: PressData, job: Job, cs: CalibrationSettings) -> tuple[str, ...]:
    """The parameters to calibrate: :func:`key_parameters` of ``arg`` (--parameters), checked to name parameters of ``press``."""
    names = key_parameters(arg, cs.parameters)
    if not names and arg is None:  # a job without [calibration] parameters, and no --parameters
        raise PressDataError(job.source, "calibration.parameters", "<missing>", NO_PARAMETERS)
    if not names:
        raise ServoPressError(f"--parameters = {one_line(arg)!r} is not valid: it names no parameter; give a comma "
                              "list such as eta_gear,mu_r or a key_parameters.json with at least one name (or leave "
                              "--parameters out for the job's list)")
    unknown = [n for n in names if n not in press.parameters]
    if unknown:
        where = ("--parameters", "--parameters") if arg is not None else (f"{job.source}", "calibration.parameters")
        raise PressDataError(where[0], where[1], unknown, f"must be parameters of the press {press.name} (known: "
                             f"{', '.join(press.parameters)}); give --parameters with names of this press, e.g. the "
                             "key_parameters.json of `servo-press sensitivity` on it, or a comma list such as eta_gear,mu_r")
    return names


def channel_map_for(log_format: Path | None, torque_unit: str, press: PressData) -> ChannelMap | None:
    """The channel map of ``--log-format`` read and checked against the press, or None; refuses ``--torque-unit``
    beside a map."""
    if log_format is None:
        return None
    if torque_unit != "N*m":
        raise PressDataError("--torque-unit", "--torque-unit", torque_unit, "is for a plain drive-log CSV: with --log-format "
                             "the channel map gives each channel's unit (unit = \"kN*m\" in the map); leave --torque-unit out")
    cmap = load_channel_map(log_format)
    cmap.check_press(press.name, press.drive.motors)
    return cmap


def read_log(path: str | Path, press: PressData, torque_unit: str = "N*m", cmap: ChannelMap | None = None) -> LogRows:
    """The rows of one drive log, read once: a plain drive-log CSV with its torque in ``torque_unit``, or, with the
    channel map ``cmap`` (checked against ``press`` by :func:`channel_map_for`), a drive trace read through it."""
    return read_log_rows(path, torque_unit) if cmap is None else read_trace_rows(path, cmap, press)


def refuse_fitted_log_as_validation(fitted: LogRows, validation: LogRows) -> None:
    """Refuse ``--validate`` naming the fitted log itself, or a copy of its data (the same data lines, whatever the
    comments say): that is no out-of-sample check. Compares the rows as read; reads nothing."""
    try:
        same = Path(fitted.source).resolve() == Path(validation.source).resolve()
    except (OSError, ValueError):
        same = False
    if same or fitted.data_key == validation.data_key:
        raise PressDataError("--validate", "--validate", validation.source, f"is {'the' if same else 'a copy of the data of the'} log "
                             f"that is fitted (--log {one_line(fitted.source)}): a validation predicts a log the fit did not see; give "
                             "another recording (another day or motion), e.g. `servo-press experiment --job cushion-validation`")
