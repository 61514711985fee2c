"""The calibration's optimisers by name, without imports: the command line's parser takes them from here without
loading the package (numpy, the press reader), and the job reader checks ``default_method`` against the same names."""

METHODS = ("aco", "least-squares", "differential-evolution")  # calibration/identification/solvers.py; a tie between two goes to the first here
