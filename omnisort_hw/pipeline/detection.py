"""Live detection: a calibration pattern found in one frame, for a person placing it.

`detect(image, pattern, model, tone)` runs the extractors the calibrations run (the extrinsic
target's markers, borders, wall/floor lines and stripe; the checkerboards target's boards and
stripe; a checkerboard's inner corners) and gives their pixels, or the extractor's reason when
it finds nothing usable, with the blue markers it did see on a wall target. Nothing is fitted,
saved, switched or logged: a screen asks again and again while the target is placed (the
operator interface's recovery and commissioning), and the calibration judges its own
detection again when it runs.

`run(rig, DetectRequest)` is the use case: the pattern from the request and the rig's cell
file, the frame from the request's image or the rig's live frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.overlays import BORDER, CORNER, FLOOR, LASER, MARKER, Colour
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import FeatureNotFoundError, InputError, NotAvailableError
from omnisort_hw.pipeline.image_files import read_image
from omnisort_hw.pipeline.replies import DetectReply, LayerReply
from omnisort_hw.pipeline.requests import DEFAULT_SQUARE_MM, DetectRequest, board_spec

REJECTED: Colour = (0, 0, 255)  # a board corner that failed its saddle check (red)
PIXEL_DECIMALS = 1  # a layer's pixels are sent to 0.1 px: finer than any screen draws
COUNTED = {"marker": "markers", "corner": "corners", "rejected": "corners rejected"}
"""The layers counted as things in a summary; the others (lines, the stripe) in pixels."""


class DetectionRig(Protocol):
    """What a live detection needs of a cell (`cell.jobs.CellJobs` is one)."""

    def camera_model(self) -> OcamModel: ...

    def tone_curve(self) -> ToneCurve: ...

    def laser_color(self) -> str: ...

    def target_defaults(self) -> tuple[str | None, float | None, str]: ...

    @property
    def registration_config(self) -> RegistrationConfig | None: ...

    def live_frame(self) -> np.ndarray:
        """A fresh frame, the laser as it is; refused at once while a measurement holds the
        camera."""
        ...


@dataclass(frozen=True)
class Pattern:
    """What to find: `what` (target, board or floor), the target's kind (two-sided,
    three-sided, checkerboards) or "checkerboard", and the board where one is looked for."""

    what: str
    kind: str
    board: BoardSpec | None = None

    @property
    def name(self) -> str:
        if self.what == "target":
            return f"the {self.kind} target"
        size = f"{self.board.cols}x{self.board.rows}" if self.board else "?"
        return f"the floor's {size} checkerboard" if self.what == "floor" else f"a {size} board"


@dataclass(frozen=True)
class Layer:
    """Pixels of one detected feature: (N, 2) px in the frame, their kind (border, floor,
    laser, marker, corner), the colour the calibration pictures draw it in, and labels."""

    name: str
    kind: str
    pixels: np.ndarray
    colour: Colour
    labels: tuple[str, ...] = ()

    def reply(self) -> LayerReply:
        b, g, r = self.colour
        return LayerReply(
            name=self.name,
            kind=self.kind,
            colour=f"#{r:02x}{g:02x}{b:02x}",
            pixels=np.round(self.pixels, PIXEL_DECIMALS).tolist(),
            labels=list(self.labels) if self.labels else None,
        )


@dataclass
class Detection:
    """The pattern's layers in one frame, or why it was not found (with what was seen)."""

    pattern: Pattern
    image: np.ndarray  # (H, W, 3) BGR: the frame searched
    layers: list[Layer] = field(default_factory=list)
    problem: str | None = None

    @property
    def found(self) -> bool:
        return self.problem is None

    def summary(self) -> str:
        """One line for people: what was found, counted, or why not."""
        if self.problem is not None:
            return f"{self.pattern.name} not found: {self.problem}"
        counts: dict[str, int] = {}
        for layer in self.layers:
            counts[layer.kind] = counts.get(layer.kind, 0) + len(layer.pixels)
        text = ", ".join(f"{n} {COUNTED.get(kind, kind + ' px')}" for kind, n in counts.items())
        return f"{self.pattern.name} found: {text}"

    def reply(self) -> DetectReply:
        h, w = self.image.shape[:2]
        return DetectReply(
            what=self.pattern.what,
            pattern=self.pattern.name,
            found=self.found,
            summary=self.summary(),
            image_width=int(w),
            image_height=int(h),
            layers=[layer.reply() for layer in self.layers],
            problem=self.problem,
        )


def _points(uv: list[np.ndarray]) -> np.ndarray:
    return np.asarray(uv, float).reshape(-1, 2)


def _target_layers(
    image: np.ndarray,
    kind: str,
    board: BoardSpec,
    model: OcamModel,
    tone: ToneCurve,
    laser_color: str = "red",
) -> list[Layer]:
    from omnisort_hw.core.laser_stripe import laser_stripe_points
    from omnisort_hw.core.target_features import extract_board_features, extract_target_features

    stripe = laser_stripe_points(image, color=laser_color)
    if kind == "checkerboards":
        boards = extract_board_features(image, model, board.size, board.square_mm, stripe)
        return [
            layer
            for name, b in boards.boards.items()
            for layer in (
                Layer(f"{name} board corners", "corner", b.corners_px, CORNER),
                Layer(f"{name} board laser", "laser", b.laser_px, LASER),
            )
        ]
    features = extract_target_features(image, model, kind=kind, tone=tone, stripe_px=stripe)
    layers = []
    for wall, f in features.walls.items():
        layers += [
            Layer(f"{wall} wall border", "border", f.border_px, BORDER),
            Layer(f"{wall} wall floor line", "floor", f.floor_px, FLOOR),
            Layer(f"{wall} wall laser", "laser", f.laser_px, LASER),
        ]
        if f.markers_px:
            labels = tuple(f"{wall[0].upper()}:{n}" for n in f.markers_px)
            pixels = _points(list(f.markers_px.values()))
            layers.append(Layer(f"{wall} wall markers", "marker", pixels, MARKER, labels))
    return layers


def _markers_seen(image: np.ndarray, tone: ToneCurve) -> list[Layer]:
    """The blue blobs a wall target's extractor saw, for a target it could not name."""
    from omnisort_hw.core.target_markers import find_blue_markers

    blobs = find_blue_markers(image, tone)
    if not blobs:
        return []
    return [Layer("blue markers seen", "marker", _points([b.uv for b in blobs]), MARKER)]


def detect(
    image: np.ndarray,
    pattern: Pattern,
    model: OcamModel | None,
    tone: ToneCurve,
    laser_color: str = "red",
) -> Detection:
    """`pattern` in `image` ((H, W, 3) BGR). `model` is needed for the targets (the extractor
    works on rays) and not for a checkerboard (commissioning finds boards before there is a
    model). A pattern not found is a Detection with its reason, not an error: a person placing
    a target is shown why; an image the camera model does not fit raises InputError."""
    from omnisort_hw.core.checkerboard import detect_board

    try:
        if pattern.what == "target":
            assert model is not None and pattern.board is not None
            layers = _target_layers(image, pattern.kind, pattern.board, model, tone, laser_color)
        else:
            assert pattern.board is not None
            found = detect_board(image, pattern.board)
            good = found.good
            layers = [Layer("board corners", "corner", found.corners[good], CORNER)]
            if not good.all():
                rejected = found.corners[~good]
                layers.append(Layer("corners rejected", "rejected", rejected, REJECTED))
    except FeatureNotFoundError as exc:
        walls = pattern.what == "target" and pattern.kind != "checkerboards"
        return Detection(pattern, image, _markers_seen(image, tone) if walls else [], str(exc))
    return Detection(pattern, image, layers)


def pattern_of(rig: DetectionRig, request: DetectRequest) -> Pattern:
    """The request's pattern, its defaults from the rig's cell file (`[target]` kind, the
    `[registration]` floor board)."""
    if request.what == "floor":
        rc = rig.registration_config
        if rc is None:
            raise NotAvailableError(
                "what=floor: the cell file has no [registration] section naming its floor board"
            )
        return Pattern("floor", "checkerboard", rc.board)
    board = board_spec(request.board, DEFAULT_SQUARE_MM, "board")
    if request.what == "board":
        return Pattern("board", "checkerboard", board)
    kind = request.target or rig.target_defaults()[0]
    if kind is None:
        raise InputError("target: which target is needed (or [target] kind in the cell file)")
    return Pattern("target", kind, board)


def run(rig: DetectionRig, request: DetectRequest) -> Detection:
    """The request's pattern in its image, or in a live frame of the rig's camera."""
    pattern = pattern_of(rig, request)
    image = read_image(request.image) if request.image is not None else rig.live_frame()
    model = rig.camera_model() if pattern.what == "target" else None
    return detect(image, pattern, model, rig.tone_curve(), rig.laser_color())
