"""The units a plain drive log's torque column may be in, without imports: the command line's parser takes them from
here without loading the package (numpy, the press reader), and the drive-log reader converts with the same table."""

TORQUE_UNITS = {"N*m": 1.0, "kN*m": 1000.0}  # unit -> factor to N m
