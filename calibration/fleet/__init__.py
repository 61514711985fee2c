"""Fleet monitoring (``monitor``): every drive log of a press calibrated, the parameters tracked over time.

* ``cluster``: finding and ordering the logs, one calibration per log on local or remote Dask workers.
* ``monitor``: the rules (baseline, parameter-change alarm, poor-fit flag).
* ``monitor_report``: trend.csv, alarms.json, trend.png and report.md.
"""
