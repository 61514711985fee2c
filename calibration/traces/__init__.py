"""Drive logs and drive traces: what the drive recorded, read onto the crank-angle grid.

* ``drive_log``: the drive-log CSV (time, crank angle, motor speed, motor torque per motor): read with safe repairs, written.
* ``trace_formats``: the named channels of a trace as its tool exported it (TwinCAT Scope CSV, NI TDMS, CSV).
* ``channel_map``: the ``--log-format MAP.toml`` that says which channel is which, in which unit.
* ``trace_log``: a trace read through its map into a drive log, with the same checks.
* ``log_identity``: which drive logs are one recording (the same samples under another name or format).
"""
