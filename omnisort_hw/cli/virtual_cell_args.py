"""The arguments of `omnisort sim virtual-cell` (run by `sim_backend.virtual_cell.run.serve`).

Declared here, outside `sim_backend`, because every `omnisort` start builds every parser:
importing the simulator to declare them would load pybullet (and print its build banner) for
`omnisort --help` and every command that never touches the simulator.
"""

from __future__ import annotations

import argparse


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """Add the virtual cell's options (scene, address, stream, controller behaviour) to `ap`."""
    ap.add_argument("--scene", default="sorting", help="scene file or shipped scene name")
    ap.add_argument("--host", default="127.0.0.2", help="address to serve on (default 127.0.0.2)")
    ap.add_argument("--width", type=int, default=None, help="camera image size (default: scene)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fps", type=float, default=10.0, help="camera stream frame rate")
    ap.add_argument("--degraded", action="store_true", help='"real camera" mode for the stream')
    ap.add_argument(
        "--effects",
        action="store_true",
        help="the stream through a real colour camera: crosstalk, chromatic aberration, bloom "
        "and Bayer demosaicing on top of --degraded, which it implies (docs/real_light.md)",
    )
    ap.add_argument(
        "--unlock-delay",
        type=float,
        default=5.0,
        help="seconds before a protective stop may be unlocked (5 on a real controller)",
    )
    ap.add_argument(
        "--gripper-output",
        default="tool:0",
        help="digital output driving the gripper, GROUP:PIN (tool, standard, configurable)",
    )
