"""The fisheye as an IP camera: an MJPEG-over-HTTP stream of the simulated cell.

`GET /stream.mjpg` sends `multipart/x-mixed-replace` JPEG parts at `fps`, what OpenCV's
FFMPEG backend (and any browser) reads as an IP camera. Query keys pick the encoding per
client: `quality` (1-100, default 95) and `sampling` ("420", the usual, or "444"); quality 100
with 4:4:4 sampling is the near-lossless option. `GET /frame.png` returns one lossless frame.

Frames show the world as it is: a renderer process (its own pybullet world of the same scene,
so rendering never stalls the controller's 500 Hz tick) draws the current state whenever it
changed and the arm is at rest. While the picture is out of date nothing is sent, so a frame
that arrives after a change always shows the state after it (a stale frame is never streamed).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import select
import socket
import threading
import time
from typing import Any
from urllib.parse import parse_qs, urlsplit

import cv2
import numpy as np
import pybullet as p

from sim_backend.virtual_cell.servers import Listener

log = logging.getLogger("virtual_cell.camera")

CAMERA_PORT = 8080
CLEAN_KEPT = 4
"""Clean pictures the renderer keeps (laser on and off of a state, and of the state before)."""


def world_state(cell: Any) -> dict[str, Any]:
    """What the picture depends on: joints, fingers, the cubes (colour, size, pose), the laser
    (switch and plane), the camera's rotation (under the cell lock)."""
    world = cell.world
    with cell.lock:
        state: dict[str, Any] = {
            "laser": bool(world.laser_on),
            "laser_plane": [*world.laser_angles_deg, float(world.laser_distance)],
            "target": target_pose(world.target_spec),
            "R_SC": np.asarray(world.R_SC, float).tolist(),
            "cubes": [],
        }
        if world.arm is not None:
            state["q"] = world.joints().tolist()
            fingers = p.getJointStates(
                world.arm.body, list(world.arm.fingers), physicsClientId=world.client
            )
            state["fingers_mm"] = float(fingers[0][0]) * 1000.0
        for spec, body in world.info.cubes:
            pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=world.client)
            state["cubes"].append([list(pos), list(orn), spec.color.name, spec.size_mm])
    return state


def target_pose(spec: Any) -> dict[str, Any] | None:
    """The target's kind and pose (what the simulator's panel changes), None when away."""
    if spec is None:
        return None
    return {"kind": spec.kind, "center_mm": list(spec.center_mm), "yaw_deg": spec.yaw_deg}


def same_picture(a: dict[str, Any] | None, b: dict[str, Any]) -> bool:
    """True when states a and b look the same to the camera: the same board held (or none),
    the camera not turned, the laser alike (switch and plane), the target alike, the same
    cubes, joints within 0.01 deg, fingers within 0.1 mm, every cube within 0.5 mm and
    0.15 deg (tolerances, not rounding, so a cube's physics jitter never makes the picture out
    of date)."""
    if a is None or a.get("board") != b.get("board"):
        return False
    if a["laser"] != b["laser"] or a["laser_plane"] != b["laser_plane"]:
        return False
    if a["target"] != b["target"]:
        return False
    if [c[2:] for c in a["cubes"]] != [c[2:] for c in b["cubes"]]:  # added or taken away
        return False
    if np.max(np.abs(np.subtract(a["R_SC"], b["R_SC"]))) >= 1e-7:  # the camera turned
        return False
    if "q" in b and np.max(np.abs(np.subtract(a["q"], b["q"]))) >= 0.01:
        return False
    if abs(a.get("fingers_mm", 0.0) - b.get("fingers_mm", 0.0)) >= 0.1:
        return False
    for (pa, oa, *_), (pb, ob, *_) in zip(a["cubes"], b["cubes"], strict=True):
        if np.max(np.abs(np.subtract(pa, pb))) >= 0.5e-3:  # pybullet metres
            return False
        if 1.0 - abs(float(np.dot(oa, ob))) >= 1e-6:  # about 0.16 deg
            return False
    return True


def _sync_cubes(cell: Any, cubes: list[list[Any]]) -> None:
    """Make the renderer's cubes those of the state: the same colours and sizes (rebuilt when
    the simulator's panel added or took one away), at the state's poses."""
    from sim_backend.scene import NAMED_COLORS, Color, CubeSpec

    world = cell.world
    have = [[spec.color.name, spec.size_mm] for spec, _ in world.info.cubes]
    if have != [c[2:] for c in cubes]:
        while world.info.cubes:
            world.remove_cube(len(world.info.cubes) - 1)
        for pos, _, color, size in cubes:
            rgb = NAMED_COLORS.get(color, (0.5, 0.5, 0.5))
            world.add_cube(CubeSpec(Color(color, rgb), size, (pos[0] * 1e3, pos[1] * 1e3)))
    for (_, body), (pos, orn, *_) in zip(world.info.cubes, cubes, strict=True):
        p.resetBasePositionAndOrientation(body, pos, orn, physicsClientId=world.client)


def _render_worker(
    scene: str, width: int, height: int, seed: int, degraded: bool, effects: bool, conn: Any
) -> None:
    """Renderer process: apply each state to its own world, send back the BGR image (and, when
    the state asks for `truth`, the renderer's truth of it). With `degraded`, the camera's
    sensor model (`sim_backend.sensor`: shot and read noise, flicker, clipping, the same fixed
    parameters as the in-process camera) exposes each state's frame at the nominal 10 ms,
    uncompressed (the stream encodes it); the noise is drawn once per rendered state, not per
    served frame. With `effects`, through the colour camera's effects as well
    (`scene.with_camera_effects`)."""
    from sim_backend.devices import SimCell
    from sim_backend.exposed_frames import ExposedFrames
    from sim_backend.scene import load_scene, with_camera_effects
    from sim_backend.scene_images import render_scene
    from sim_backend.sensor import Exposure
    from sim_backend.virtual_cell.held_board import held_board_scene

    world_scene = load_scene(scene)
    if effects:
        world_scene = with_camera_effects(world_scene)
    cell = SimCell.from_scene(world_scene, seed=seed, width=width, height=height)
    world = cell.world
    sensor = ExposedFrames(world, cell.model, seed, cell.lighting) if degraded else None
    # The held board's pictures and truths, by pose (each rendered once).
    held: dict[int, tuple[np.ndarray, dict[str, Any]]] = {}
    # The last clean pictures (state, image): a measurement's laser-on and laser-off
    # frames alternate between two states, each rendered once.
    clean: list[tuple[dict[str, Any], np.ndarray]] = []
    conn.send(("ready", None, None))
    n = 0
    while True:
        try:
            state = conn.recv()
        except EOFError:
            return
        if state is None:
            return
        view = state.get("board")
        if view is not None:
            if view not in held:
                board = held_board_scene(cell.scene, view)
                held[view] = render_scene(board, seed=seed + view, degraded=degraded)
            board_image, board_truth = held[view]
            conn.send(("image", board_image, board_truth if state.get("truth") else None))
            continue
        if world.arm is not None and "q" in state:
            world.set_joints(np.asarray(state["q"]))
            world.set_fingers(state["fingers_mm"])
        _sync_cubes(cell, state["cubes"])
        target = state["target"]
        if target != target_pose(world.target_spec):
            if target is None:
                cell.set_target(False)
            else:
                cell.set_target(True, target["kind"], tuple(target["center_mm"]), target["yaw_deg"])
        world.laser_on = state["laser"]
        cell.set_laser_plane(*state["laser_plane"])
        world.R_SC = np.asarray(state["R_SC"], float)
        n += 1
        truth: dict[str, Any] | None = None
        if sensor is not None:
            settings = Exposure(
                laser_on=bool(state["laser"]),
                flicker_depth=cell.lighting.flicker_depth,
                pixel_format="BGR3",
            )
            image, _ = sensor.frame(settings, n)
            if state.get("truth"):
                _, truth = cell.render(seed + n, False, with_truth=True)
        else:
            # A truth asked for is the renderer's own of this very state: never from the cache.
            want_truth = bool(state.get("truth"))
            kept = (
                None if want_truth else next((k for k in clean if same_picture(k[0], state)), None)
            )
            if kept is None:
                image, truth = cell.render(seed + n, False, with_truth=want_truth)
                clean[:] = [*clean[-(CLEAN_KEPT - 1) :], (state, image)]
            else:
                image, truth = kept[1], None
        conn.send(("image", image, truth))


class FrameSource:
    """The latest rendered frame and the state it shows; renders on demand in a subprocess."""

    def __init__(
        self,
        cell: Any,
        controller: Any,
        scene: str,
        seed: int = 0,
        degraded: bool = False,
        effects: bool = False,
    ) -> None:
        self.cell, self.controller = cell, controller
        cam = cell.scene.camera
        self.width, self.height = cam.width, cam.height
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_render_worker,
            args=(scene, self.width, self.height, seed, degraded, effects, child),
            name="virtual-cell-renderer",
            daemon=True,
        )
        self.image: np.ndarray | None = None
        self.shown: dict[str, Any] | None = None  # the state the image shows
        self.key = 0  # which frame (for the encoding cache)
        self.renders = 0
        self.clients = 0
        self.cond = threading.Condition()
        self._pipe = threading.Lock()  # one request to the renderer at a time
        self.stop = threading.Event()
        self._encoded: dict[tuple, bytes] = {}
        self.board: int | None = None  # the pose of the board held in front of the camera
        self._thread = threading.Thread(target=self._run, name="camera-render", daemon=True)

    def start(self, timeout_s: float = 60.0) -> None:
        self._proc.start()
        if not self._conn.poll(timeout_s):
            raise RuntimeError("the camera renderer did not start")
        self._conn.recv()
        self._render(timeout_s)  # the first frame is there before the cell says ready
        self._thread.start()

    def _render(
        self, timeout_s: float, truth: bool = False
    ) -> tuple[np.ndarray, dict[str, Any]] | None:
        """Render the world's current state: (image, the renderer's truth of it when `truth`
        is asked, else {}); None if stopped or the renderer died."""
        state = self.state()
        with self._pipe:
            self._conn.send({**state, "truth": truth})
            deadline = time.monotonic() + timeout_s
            while not self._conn.poll(0.5):
                if self.stop.is_set() or not self._proc.is_alive() or time.monotonic() > deadline:
                    return None
            _, image, found = self._conn.recv()
        with self.cond:
            self.image, self.shown = image, state
            self.key += 1
            self._encoded.clear()
            self.renders += 1
            self.cond.notify_all()
        return image, found or {}

    def snapshot(self, timeout_s: float = 120.0) -> tuple[np.ndarray, dict[str, Any]]:
        """A picture of the world as it is now, with the renderer's truth of it (the arm at
        rest: a picture is never taken mid-move); RuntimeError when none can be made."""
        deadline = time.monotonic() + timeout_s
        while self.controller is not None and self.controller.moving:
            if time.monotonic() > deadline:
                raise RuntimeError("render: the arm did not come to rest")
            time.sleep(0.02)
        made = self._render(max(1.0, deadline - time.monotonic()), truth=True)
        if made is None:
            raise RuntimeError("render: the renderer did not answer")
        return made

    def current(self) -> bool:
        """True when the latest frame shows the world as it is now (never while the arm
        moves)."""
        if self.controller is not None and self.controller.moving:
            return False
        return same_picture(self.shown, self.state())

    def state(self) -> dict[str, Any]:
        """What the next picture shows: the world's state, and the board held."""
        return {**world_state(self.cell), "board": self.board}

    def hold_board(self, view: int | None, timeout_s: float = 60.0) -> bool:
        """Hold the board at pose `view` (None: put it down); True once a picture shows it
        (at once when no client watches: the next picture will)."""
        self.board = view
        return self.wait_shown(timeout_s)

    def wait_shown(self, timeout_s: float = 60.0) -> bool:
        """True once a picture shows the state as it is now (at once when no client watches:
        the next picture will); False after `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        while self.clients > 0 and not self.current():
            if self.stop.is_set() or time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True

    def _run(self) -> None:
        while not self.stop.is_set():
            if self.clients == 0:
                time.sleep(0.05)
                continue
            moving = self.controller is not None and self.controller.moving
            if moving or same_picture(self.shown, self.state()):
                time.sleep(0.02)
                continue
            if self._render(600.0) is None:
                return

    def encoded(self, quality: int, sampling: str) -> tuple[int, bytes | None]:
        """(key, JPEG bytes) of the latest frame at this quality (cached per frame)."""
        with self.cond:
            image, key = self.image, self.key
            if image is None:
                return key, None
            cached = self._encoded.get((quality, sampling))
        if cached is None:
            params = [cv2.IMWRITE_JPEG_QUALITY, quality]
            if sampling == "444":
                params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
            ok, buf = cv2.imencode(".jpg", image, params)
            cached = buf.tobytes() if ok else b""
            with self.cond:
                if self.key == key:
                    self._encoded[(quality, sampling)] = cached
        return key, cached

    def close(self) -> None:
        self.stop.set()
        with contextlib.suppress(OSError, BrokenPipeError):
            self._conn.send(None)
        self._proc.join(2.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(2.0)


def _writable(sock: socket.socket) -> bool:
    """True when the socket can take more data now (the client keeps reading)."""
    return bool(select.select([], [sock], [], 0)[1])


def _send_all(sock: socket.socket, data: bytes, stop: threading.Event) -> None:
    """Send a whole part (never half a frame), however slowly the client reads; the server
    stopping ends it."""
    view = memoryview(data)
    while view:
        if stop.is_set():
            raise OSError("server stopping")
        try:
            sent = sock.send(view)
        except TimeoutError:
            continue
        view = view[sent:]


class CameraStreamServer:
    """HTTP on host:port: /stream.mjpg (MJPEG) and /frame.png (one lossless frame)."""

    def __init__(
        self,
        host: str,
        frames: FrameSource,
        faults: Any,
        port: int = CAMERA_PORT,
        fps: float = 10.0,
    ) -> None:
        self.frames, self.faults, self.fps = frames, faults, fps
        self.listener = Listener(host, port, self._handle, "camera")
        self.frames_sent = 0

    def _handle(self, sock: socket.socket) -> None:
        stop = self.listener.stop
        request = b""
        while b"\r\n\r\n" not in request:
            try:
                chunk = sock.recv(4096)
            except TimeoutError:
                if stop.is_set():
                    return
                continue
            if not chunk or len(request) > 16384:
                return
            request += chunk
        line = request.split(b"\r\n", 1)[0].decode(errors="replace").split()
        if len(line) < 2 or line[0] != "GET":
            sock.sendall(b"HTTP/1.0 405 Method Not Allowed\r\n\r\n")
            return
        url = urlsplit(line[1])
        query = {k: v[-1] for k, v in parse_qs(url.query).items()}
        try:
            quality = int(query.get("quality", 95))
            sampling = query.get("sampling", "420")
            if not 1 <= quality <= 100 or sampling not in ("420", "444"):
                raise ValueError
        except ValueError:
            sock.sendall(b"HTTP/1.0 400 Bad Request\r\n\r\nquality 1-100, sampling 420|444\r\n")
            return
        if url.path in ("/", "/stream.mjpg"):
            self._stream(sock, quality, sampling)
        elif url.path == "/frame.png":
            self._png(sock)
        else:
            sock.sendall(b"HTTP/1.0 404 Not Found\r\n\r\n")

    def _wait_current(self, stop: threading.Event) -> int | None:
        """Block until the latest frame shows the current state; its number."""
        frames = self.frames
        while not stop.is_set():
            self.faults.wait("camera", stop)
            if frames.image is not None and frames.current():
                return frames.key
            with frames.cond:
                frames.cond.wait(0.05)
        return None

    def _png(self, sock: socket.socket) -> None:
        frames = self.frames
        frames.clients += 1
        try:
            image = frames.image if self._wait_current(self.listener.stop) is not None else None
            if image is None:
                return
            _, buf = cv2.imencode(".png", image)
        finally:
            frames.clients -= 1
        data = buf.tobytes()
        sock.sendall(
            b"HTTP/1.0 200 OK\r\nContent-Type: image/png\r\n"
            + f"Content-Length: {len(data)}\r\n\r\n".encode()
            + data
        )

    def _stream(self, sock: socket.socket, quality: int, sampling: str) -> None:
        stop = self.listener.stop
        frames = self.frames
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 256 * 1024)
        sock.sendall(
            b"HTTP/1.0 200 OK\r\nCache-Control: no-cache\r\nConnection: close\r\n"
            b"Content-Type: multipart/x-mixed-replace; boundary=frame\r\n\r\n"
        )
        frames.clients += 1
        period = 1.0 / self.fps
        try:
            while not stop.is_set():
                t0 = time.monotonic()
                if self._wait_current(stop) is None:
                    return
                _, data = frames.encoded(quality, sampling)
                if not data or not _writable(sock):
                    time.sleep(period)  # the client is not reading: drop frames, keep it
                    continue
                part = (
                    b"--frame\r\nContent-Type: image/jpeg\r\n"
                    + f"Content-Length: {len(data)}\r\n\r\n".encode()
                    + data
                    + b"\r\n"
                )
                _send_all(sock, part, stop)
                self.frames_sent += 1
                time.sleep(max(0.0, period - (time.monotonic() - t0)))
        finally:
            frames.clients -= 1
