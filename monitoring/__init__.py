"""The calibrated model as a tonnage monitor: the slide force of every stroke from the drive's own signals (virtual
tonnage), per-stroke records in OPC 40503's terms stored as Parquet and queried with DuckDB, and alarms on the force
band and on drift. Above ``calibration`` (it reads a calibration's parameters and joint region), below the commands."""
