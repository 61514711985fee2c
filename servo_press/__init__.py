"""The command layer: argument parsing, one function per ``servo-press`` subcommand, and ``reproduce``.

The top floor: the one package that imports all three (``press_model``, ``calibration``, ``planning``);
everything below it flows one way: press data -> model -> responses -> sensitivity / calibration -> planning.
"""
