"""The cell in 3D (NiceGUI's `ui.scene`, three.js): the camera's frame, the laser plane, the
last map's points coloured by their sigma, the last located cubes, the robot base, its bins
and the arm as it stands. The geometry is the service's `geometry` reply (system.json,
`[sorting]`, the arm's joints through the core's forward kinematics); the points and the cubes
are the replies of the last `map` and `locate` this interface started. The page only draws:
S in metres, shifted so the floor the robot stands on is the grid's plane.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from nicegui import run, ui

from omnisort_hw.pipeline.replies import GeometryReply, LocateReply, MapReply
from omnisort_hw.ui.context import UiContext
from omnisort_hw.ui.link import CellCommands, ClientError, CommandError, call_of
from omnisort_hw.ui.overlay_svg import sigma_rgb
from omnisort_hw.ui.widgets import tag

At = Callable[[Sequence[float] | np.ndarray], list[float]]
"""A point in S (mm) where the scene draws it (m, about the view's centre)."""

MM = 1e-3  # the scene's unit is the metre
GEOMETRY = call_of(CellCommands.geometry)
CUBE_COLOURS = {
    "red": "#d01818",
    "green": "#18a030",
    "blue": "#1850d8",
    "yellow": "#e8cc18",
}
SHOWN_FPS = 20
HIDDEN_FPS = 1
"""Frames a second the scene draws while its tab is shown, and while hidden. Once its tab has
been opened, three.js draws the scene for good (the tab panels keep it alive), in software
where the PC has no GPU: at 20 fps a hidden scene kept a browser's renderer so busy, on a
loaded 2-core PC, that it stopped answering for over 10 s."""
LASER_COLOUR = "#ff2020"
ARM_COLOUR = "#5a6470"


class Cell3D:
    """`build()` in a container; `refresh()` (a timer) asks `geometry` every few seconds while
    shown and redraws when it, the last map or the last location changed."""

    def __init__(self, ctx: UiContext) -> None:
        self.ctx = ctx
        self.visible = False
        self.drawn: dict[str, int] = {}  # what the scene holds now, counted (for the legend)
        self._key: tuple[object, ...] | None = None
        self._ticks = 0
        self._busy = False
        self._looked = False  # the view is set once; then it is the person's

    def build(self) -> None:
        with ui.card().classes("w-full"):
            with ui.row().classes("items-center gap-4"):
                ui.label("The cell in 3D").classes("text-lg")
                self.legend = tag(ui.label(""), "scene-legend").classes("text-sm")
            self.scene = tag(
                ui.scene(
                    width=800,
                    height=540,
                    grid=(8, 16),
                    background_color="#f4f5f7",
                    fps=HIDDEN_FPS,
                ),
                "scene-3d",
            )
            ui.label(
                "Drag to turn, scroll to zoom. S in metres; the grid is the floor the robot "
                "stands on, 0.5 m squares."
            ).classes("text-xs text-gray-600")

    def show(self, visible: bool) -> None:
        self.visible = visible
        if visible:
            self._ticks = 0
        # Set as a number, as the prop is declared (`props("fps=1")` would send a string).
        self.scene._props["fps"] = SHOWN_FPS if visible else HIDDEN_FPS
        self.scene.update()

    async def refresh(self) -> None:
        """Every 4th tick while shown: the geometry, then a redraw if anything changed."""
        if not self.visible or self._busy:
            return
        self._ticks += 1
        if self._ticks % 4 != 1:
            return
        self._busy = True
        try:
            geometry = await run.io_bound(self.ctx.link.call, GEOMETRY)
        except (CommandError, ClientError) as exc:
            self.legend.text = f"no geometry: {exc}"
            return
        finally:
            self._busy = False
        if geometry is None:
            return
        mapped = self.ctx.jobs.result(CellCommands.map)
        located = self.ctx.jobs.result(CellCommands.locate)
        key = (repr(geometry), id(mapped), id(located))
        if key != self._key:
            self._key = key
            self.draw(geometry, mapped, located)

    # -- drawing --------------------------------------------------------------------------

    def draw(
        self, geometry: GeometryReply, map_reply: MapReply | None, located: LocateReply | None
    ) -> None:
        """Everything again, from the replies (S in mm) to the scene (metres above the floor)."""
        floor = geometry.floor_z_mm
        lift = np.array([0.0, 0.0, -(floor if floor is not None else -1000.0)]) * MM
        s = self.scene
        s.clear()
        drawn: dict[str, int] = {}

        def at(p_mm: Sequence[float] | np.ndarray) -> list[float]:
            return (np.asarray(p_mm, float) * MM + lift).tolist()

        def polyline(points_mm: Sequence[Sequence[float]], colour: str, closed: bool) -> None:
            pts = [at(p) for p in points_mm]
            for a, b in zip(pts, pts[1:] + pts[:1] if closed else pts[1:], strict=False):
                s.line(a, b).material(colour)

        R = geometry.camera_R_SC
        if R is not None:
            origin = at([0.0, 0.0, 0.0])
            s.axes_helper(0.25).rotate_R(R).move(*origin)
            s.sphere(0.03).material("#222222").move(*origin)
            s.text("camera", "font-size: 0.8em").move(*origin)
            drawn["camera"] = 1
        plane = geometry.laser_plane
        if plane is not None:
            polyline(plane.corners_S_mm, LASER_COLOUR, closed=True)
            c = np.asarray(plane.corners_S_mm, float)
            for a, b in ((c[0], c[2]), (c[1], c[3])):
                s.line(at(a), at(b)).material(LASER_COLOUR, opacity=0.5)
            drawn["laser plane"] = 1
        if geometry.robot_base_T_SB is not None:
            T = np.asarray(geometry.robot_base_T_SB, float)
            s.axes_helper(0.2).rotate_R(T[:3, :3].tolist()).move(*at(T[:3, 3]))
            s.text("robot base", "font-size: 0.8em").move(*at(T[:3, 3]))
        if geometry.arm is not None:
            points = geometry.arm.points_S_mm
            polyline(points, ARM_COLOUR, closed=False)
            for p in points:
                s.sphere(0.025).material(ARM_COLOUR).move(*at(p))
            drawn["arm joints"] = len(points)
        for b in geometry.bins:
            colour = CUBE_COLOURS.get(b.color, "#888888")
            polyline(b.corners_S_mm, colour, closed=True)
            polyline(b.floor_S_mm, colour, closed=True)
            for top, foot in zip(b.corners_S_mm, b.floor_S_mm, strict=True):
                s.line(at(top), at(foot)).material(colour)
            drawn["bins"] = drawn.get("bins", 0) + 1
        self._draw_points(map_reply, at, drawn)
        size = geometry.cube_size_mm * MM
        for cube in located.cubes if located is not None else []:
            yaw = np.radians(cube.yaw_S_deg)
            s.box(size, size, size).material(CUBE_COLOURS.get(cube.color, "#888888")).rotate(
                0.0, 0.0, yaw
            ).move(*at(cube.center_S_mm))
            drawn["cubes"] = drawn.get("cubes", 0) + 1
        if not self._looked:
            self._looked = True
            # Over the boom's shoulder, towards the work area and the bins beyond it.
            s.move_camera(
                x=2.0, y=-1.0, z=1.5, look_at_x=0.0, look_at_y=0.8, look_at_z=0.5, duration=0.0
            )
        self.drawn = drawn
        problems = "; ".join(geometry.problems)
        self.legend.text = ", ".join(f"{k}: {v}" for k, v in drawn.items()) + (
            f" ({problems})" if problems else ""
        )

    def _draw_points(self, reply: MapReply | None, at: At, drawn: dict[str, int]) -> None:
        """The last map's points, coloured by their sigma across the plane (as on the live
        view: green at the smallest, red at the largest)."""
        points = (reply.points_S if reply is not None else None) or []
        sigma = (reply.sigma_normal_mm if reply is not None else None) or []
        if not points or len(sigma) != len(points):
            return
        lo, hi = min(sigma), max(sigma)
        colours = [list(sigma_rgb(v, lo, hi)) for v in sigma]
        self.scene.point_cloud([at(p) for p in points], colours, point_size=0.03)
        drawn["map points"] = len(points)
