"""The command layer: argument parsing, one function per ``servo-press`` subcommand, and ``reproduce``.

This is the one place that imports all three packages (``press_model``, ``calibration``, ``planning``);
everything below it flows one way: press data -> model -> responses -> sensitivity / calibration -> planning.
"""
