"""The names and ranges the core accepts, in a module that imports nothing: the cell file's
loader, the core itself and the commands' declarations (`pipeline.requests`, read at every
`omnisort` start) name them from here without loading numpy."""

TARGETS = ("two-sided", "three-sided", "checkerboards")
"""The extrinsic calibration targets."""
METHODS_FOR = {
    "two-sided": ("joint", "paper"),
    "three-sided": ("joint", "method1"),
    "checkerboards": ("method2",),
}
"""The calibration methods each target supports, its default first."""
METHODS = tuple(dict.fromkeys(m for methods in METHODS_FOR.values() for m in methods))
"""Every method, once each."""
REFINEMENTS = ("auto", "saddle", "plane")
"""How an intrinsic calibration refines its board corners."""
DEFAULT_BOARD = "9x6"
"""Inner corners COLSxROWS of a checkerboard when none is named (the paper's boards)."""
SQUARE_RANGE_MM = (1.0, 1000.0)
"""What a checkerboard's square can be: below 1 mm no fisheye pixel resolves it at a cell's
distances; 1 m squares make a 9x6 board 10 m x 7 m, larger than a cell (a square given in
micrometres or metres by mistake lands outside)."""
LASER_COLORS = ("red", "green", "blue")
"""The line lasers' colours the stripe extractor knows (industrial line lasers come in all
three; blue is common on shiny metal); the cell file's `[laser] color`, red by default."""
