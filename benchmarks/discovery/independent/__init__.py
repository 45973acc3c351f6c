"""Independent case generator of the discovery benchmark (issue 19, item 9).

A second simulator of the seed paper's fast-tool-servo machine, written from the
machine file and the paper (Eqs 1-7) without servosurf's loop, sweep, noise
synthesis or diagnosis code: its own plant, controller, time integration, surface
generation and noise. See ``README.md`` in this folder.
"""
