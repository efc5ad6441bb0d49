"""Forward and analytic inverse kinematics of the UR e-series (UR3e, UR5e, UR10e), vectorised.

Conventions (see docs/frames.md): poses are 4x4 homogeneous transforms of the
flange (tool0) in the UR base frame B, translations in millimetres; joint angles are in
degrees at every public boundary. Arrays carry any number of leading batch axes, OpenCV
calib3d style: `q` is (..., 6), a pose is (..., 4, 4).

The arm is described by UR's published standard DH parameters
(T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i), alpha = [pi/2, 0, 0, pi/2, -pi/2, 0]).
The inverse is the usual closed form for this geometry (Hawkins, "Analytic inverse
kinematics for the Universal Robots UR-5/UR-10 arms", 2013): theta1 from the wrist centre,
theta5 from theta1 and the flange position, theta6 from the flange orientation, then the
planar three-link problem for theta2..theta4. It gives up to 8 branches, indexed
`4 * shoulder + 2 * wrist + elbow` where each bit picks the second sign of that square root:
shoulder 0/1 = theta1 = phi + asin(d4 / r) or phi + pi - asin(d4 / r); wrist 0/1 =
sin(theta5) >= 0 or <= 0; elbow 0/1 = sin(theta3) >= 0 or <= 0.

Singular configurations (Jacobian rank drops):
- wrist: sin(theta5) = 0, axes 4 and 6 are parallel; theta6 is free and set to a hint;
- elbow: sin(theta3) = 0, the arm is stretched or folded (edge of the workspace);
- shoulder: the wrist centre lies on the cylinder of radius d4 around axis 1, where the two
  shoulder branches meet.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from omnisort_hw.core.frames import as_batch, invert_pose
from omnisort_hw.errors import MotionRefusedError

UR_ALPHA_RAD = (np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0)

# Tolerance on the cosines of theta1's offset, theta5 and theta3 before a branch is declared
# out of reach; within it the cosine is clipped to [-1, 1]. 1e-9 moves the flange < 1e-6 mm.
_REACH_EPS = 1e-9
# Below this |sin(theta5)| theta6 is numerically undetermined and the hint is used instead.
_WRIST_DEGENERATE = 1e-10


class UnreachableError(MotionRefusedError):
    """The pose is outside the arm's workspace: no inverse kinematics branch exists."""

    code = "unreachable"


class JointLimitError(MotionRefusedError):
    """The pose is reachable, but no solution has every joint within its limits."""

    code = "joint_limit"


class SingularPoseError(MotionRefusedError):
    """The pose (or a path) is at or too near a singular configuration of the arm."""

    code = "singular_pose"


@dataclass(frozen=True)
class URModel:
    """A UR arm: standard DH parameters (mm, rad) and joint limits (deg), base joint first.

    `limits_deg` holds (min, max) per joint; `max_speed_deg_s` is the controller's hard
    maximum joint speed from UR's data sheet, for checking requested motion limits.
    """

    name: str
    d_mm: tuple[float, float, float, float, float, float]
    a_mm: tuple[float, float, float, float, float, float]
    limits_deg: tuple[tuple[float, float], ...]
    max_speed_deg_s: tuple[float, float, float, float, float, float]
    alpha_rad: tuple[float, float, float, float, float, float] = UR_ALPHA_RAD

    def __post_init__(self) -> None:
        d, a, alpha = self.d, self.a, self.alpha
        if d.shape != (6,) or a.shape != (6,) or alpha.shape != (6,):
            raise ValueError(f"{self.name}: DH parameters need 6 values each")
        if not (
            np.allclose(alpha, UR_ALPHA_RAD)
            and np.all(a[[0, 3, 4, 5]] == 0.0)
            and np.all(d[[1, 2]] == 0.0)
        ):
            raise ValueError(
                f"{self.name}: the analytic inverse needs UR geometry: alpha = "
                "[pi/2, 0, 0, pi/2, -pi/2, 0], a1 = a4 = a5 = a6 = 0, d2 = d3 = 0"
            )
        lim = self.limits
        if lim.shape != (6, 2) or np.any(lim[:, 0] >= lim[:, 1]):
            raise ValueError(f"{self.name}: limits_deg needs 6 (min, max) pairs with min < max")

    @property
    def d(self) -> np.ndarray:
        """DH offsets d_i along z_{i-1}, mm, shape (6,)."""
        return np.array(self.d_mm, dtype=float)

    @property
    def a(self) -> np.ndarray:
        """DH lengths a_i along x_i, mm, shape (6,)."""
        return np.array(self.a_mm, dtype=float)

    @property
    def alpha(self) -> np.ndarray:
        """DH twists alpha_i about x_i, rad, shape (6,)."""
        return np.array(self.alpha_rad, dtype=float)

    @property
    def limits(self) -> np.ndarray:
        """Joint limits, deg, shape (6, 2) as (min, max) rows."""
        return np.array(self.limits_deg, dtype=float)

    @property
    def reach_mm(self) -> float:
        """Distance from the shoulder axis to the wrist centre with the arm stretched."""
        return float(abs(self.a_mm[1]) + abs(self.a_mm[2]))

    def with_limits(self, limits_deg: np.ndarray | tuple[tuple[float, float], ...]) -> URModel:
        """A copy of this model with other joint limits (deg, (6, 2))."""
        lim = np.asarray(limits_deg, dtype=float)
        return dataclasses.replace(self, limits_deg=tuple((float(lo), float(hi)) for lo, hi in lim))


def _ur(
    name: str,
    d_m: tuple[float, float, float, float],
    a_m: tuple[float, float],
    max_speed: tuple[float, float, float, float, float, float],
) -> URModel:
    """A UR model from UR's published figures in metres: (d1, d4, d5, d6) and (a2, a3)."""
    d1, d4, d5, d6 = (round(v * 1000.0, 6) for v in d_m)
    a2, a3 = (round(v * 1000.0, 6) for v in a_m)
    # UR's data sheets give +-360 deg for every joint; the elbow cannot physically turn past
    # about +-180 deg (the shoulder is in the way), which UR's own ROS description also uses.
    limits = ((-360.0, 360.0), (-360.0, 360.0), (-180.0, 180.0)) + ((-360.0, 360.0),) * 3
    return URModel(
        name=name,
        d_mm=(d1, 0.0, 0.0, d4, d5, d6),
        a_mm=(0.0, a2, a3, 0.0, 0.0, 0.0),
        limits_deg=limits,
        max_speed_deg_s=max_speed,
    )


# DH parameters from Universal Robots' "Parameters for calculations of kinematics and
# dynamics" (e-Series, software 5.1); maximum joint speeds from the e-Series data sheets.
UR3E = _ur(
    "ur3e",
    (0.15185, 0.13105, 0.08535, 0.0921),
    (-0.24355, -0.2132),
    (180.0, 180.0, 180.0, 360.0, 360.0, 360.0),
)
UR5E = _ur("ur5e", (0.1625, 0.1333, 0.0997, 0.0996), (-0.425, -0.3922), (180.0,) * 6)
UR10E = _ur(
    "ur10e",
    (0.1807, 0.17415, 0.11985, 0.11655),
    (-0.6127, -0.57155),
    (120.0, 120.0, 180.0, 180.0, 180.0, 180.0),
)
UR_MODELS: dict[str, URModel] = {m.name: m for m in (UR3E, UR5E, UR10E)}


def get_model(name: str) -> URModel:
    """The UR model called `name` (case-insensitive), or a ValueError listing the known ones."""
    try:
        return UR_MODELS[name.lower()]
    except KeyError:
        raise ValueError(f"unknown UR model {name!r}; known: {', '.join(UR_MODELS)}") from None


# ---------------------------------------------------------------------------------------------
# Joint angles


def wrap_deg(q: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-180, 180) deg."""
    return (np.asarray(q, dtype=float) + 180.0) % 360.0 - 180.0


# ---------------------------------------------------------------------------------------------
# Forward kinematics


def _dh_trig(alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of the DH twists with the exact 0 / +-1 for multiples of pi/2."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    return np.where(np.abs(ca) < 1e-12, 0.0, ca), np.where(np.abs(sa) < 1e-12, 0.0, sa)


def _chain(model: URModel, q_rad: np.ndarray, keep_all: bool) -> list[np.ndarray]:
    """Frames 0..6 (or only 6) as (N, 4, 4), from column-wise DH products (no 4x4 matmuls).

    Each step applies Rz(theta) Tz(d) Tx(a) Rx(alpha) to the current frame's columns.
    """
    n = q_rad.shape[0]
    d, a = model.d, model.a
    ca, sa = _dh_trig(model.alpha)
    x = np.zeros((3, n))
    y = np.zeros((3, n))
    z = np.zeros((3, n))
    p = np.zeros((3, n))
    x[0], y[1], z[2] = 1.0, 1.0, 1.0
    frames: list[np.ndarray] = []

    def pack() -> np.ndarray:
        T = np.zeros((n, 4, 4))
        T[:, :3, 0], T[:, :3, 1], T[:, :3, 2], T[:, :3, 3] = x.T, y.T, z.T, p.T
        T[:, 3, 3] = 1.0
        return T

    if keep_all:
        frames.append(pack())
    c_all, s_all = np.cos(q_rad.T), np.sin(q_rad.T)
    for i in range(6):
        c, s = c_all[i], s_all[i]
        xr = c * x + s * y
        yr = c * y - s * x
        p = p + d[i] * z + a[i] * xr
        y_new = ca[i] * yr + sa[i] * z
        z = ca[i] * z - sa[i] * yr
        x, y = xr, y_new
        if keep_all:
            frames.append(pack())
    if not keep_all:
        frames.append(pack())
    return frames


def forward(model: URModel, q_deg: np.ndarray, tool: np.ndarray | None = None) -> np.ndarray:
    """Flange pose in B (..., 4, 4), mm, for joints q (..., 6) deg; `tool` (4, 4) is appended."""
    q, batch = as_batch(q_deg, (6,), "q_deg")
    T = _chain(model, np.radians(q), keep_all=False)[0]
    if tool is not None:
        T = T @ np.asarray(tool, dtype=float)
    return T.reshape(*batch, 4, 4)


def joint_frames(model: URModel, q_deg: np.ndarray) -> np.ndarray:
    """All DH frames 0..6 in B (..., 7, 4, 4), mm: frame 0 is B, frame 6 the flange.

    Frame i sits at the end of link i; joint i+1 turns about its z axis.
    """
    q, batch = as_batch(q_deg, (6,), "q_deg")
    frames = np.stack(_chain(model, np.radians(q), keep_all=True), axis=1)
    return frames.reshape(*batch, 7, 4, 4)


# ---------------------------------------------------------------------------------------------
# Inverse kinematics


@dataclass(frozen=True)
class IKSolutions:
    """All 8 analytic branches for each pose; leading axes as the poses given.

    q: (..., 8, 6) deg in [-180, 180), NaN where the branch does not exist;
    valid: (..., 8) True where the branch exists (its FK reproduces the pose);
    wrist_singular, elbow_singular, shoulder_singular: (..., 8) the branch is within
    `singular_tol` of that singularity (see `inverse`).
    """

    q: np.ndarray
    valid: np.ndarray
    wrist_singular: np.ndarray
    elbow_singular: np.ndarray
    shoulder_singular: np.ndarray

    @property
    def singular(self) -> np.ndarray:
        """(..., 8) the branch is near any singularity."""
        return self.wrist_singular | self.elbow_singular | self.shoulder_singular

    @property
    def reachable(self) -> np.ndarray | np.bool_:
        """(...) at least one branch exists."""
        return self.valid.any(axis=-1)


def inverse(
    model: URModel,
    T: np.ndarray,
    *,
    tool: np.ndarray | None = None,
    q6_hint_deg: float | np.ndarray = 0.0,
    singular_tol: float = 1e-6,
) -> IKSolutions:
    """All inverse kinematics branches of flange poses T (..., 4, 4) in B, mm.

    With `tool` (4, 4), T is the tool pose and the flange pose is T @ inv(tool).
    `q6_hint_deg` (scalar or (...)) is used for theta6 where it is undetermined (wrist
    singular); pass the current wrist 3 angle to stay put. `singular_tol` sets the flags:
    wrist |sin theta5| < tol, elbow |sin theta3| < tol, shoulder: horizontal distance of the
    wrist centre from the singular cylinder < tol * reach.
    """
    Tf, batch = as_batch(T, (4, 4), "T")
    if tool is not None:
        Tf = Tf @ invert_pose(np.asarray(tool, dtype=float))
    n = Tf.shape[0]
    m = np.ascontiguousarray(Tf.reshape(n, 16).T)
    x6x, x6y, x6z = m[0], m[4], m[8]
    y6x, y6y, y6z = m[1], m[5], m[9]
    z6x, z6y, z6z = m[2], m[6], m[10]
    p6x, p6y, p6z = m[3], m[7], m[11]
    d1, _, _, d4, d5, d6 = model.d_mm
    a2, a3 = model.a_mm[1], model.a_mm[2]
    hint = np.broadcast_to(np.radians(np.asarray(q6_hint_deg, dtype=float)), batch).reshape(n)

    # theta1 (shoulder branch, axis 0): the wrist centre p5 lies d4 off the arm's plane.
    p5x, p5y, p5z = p6x - d6 * z6x, p6y - d6 * z6y, p6z - d6 * z6z
    r = np.hypot(p5x, p5y)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(r > 0.0, d4 / r, np.inf)
    ok1 = ratio <= 1.0 + _REACH_EPS
    ratio = np.minimum(ratio, 1.0)
    phi = np.arctan2(p5y, p5x)
    off = np.arcsin(ratio)
    t1 = np.stack([phi + off, phi + np.pi - off])  # (2, n)
    horiz = r * np.sqrt(1.0 - ratio * ratio)  # wrist centre distance from singular cylinder
    c1, s1 = np.cos(t1), np.sin(t1)

    # theta5 (wrist branch, axis 1): the flange's offset along the shoulder axis n1.
    c5 = (p6x * s1 - p6y * c1 - d4) / d6
    ok5 = np.abs(c5) <= 1.0 + _REACH_EPS
    c5 = np.clip(c5, -1.0, 1.0)
    s5abs = np.sqrt(1.0 - c5 * c5)
    s5 = np.stack([s5abs, -s5abs], axis=1)  # (2, 2, n)
    c5 = c5[:, None]

    # theta6 from the flange axes' components along n1: x6.n1 = s5 c6, y6.n1 = -s5 s6.
    xn = (x6x * s1 - x6y * c1)[:, None]
    yn = (y6x * s1 - y6y * c1)[:, None]
    sgn = np.where(s5 < 0.0, -1.0, 1.0)
    degenerate = (s5abs < _WRIST_DEGENERATE)[:, None]
    t6 = np.where(degenerate, hint, np.arctan2(-yn * sgn, xn * sgn))
    c6, s6 = np.cos(t6), np.sin(t6)

    # Frame 4 from the flange: x4 = c5 (c6 x6 - s6 y6) - s5 z6, z4 = -s6 x6 - c6 y6.
    x4x = c5 * (c6 * x6x - s6 * y6x) - s5 * z6x
    x4y = c5 * (c6 * x6y - s6 * y6y) - s5 * z6y
    x4z = c5 * (c6 * x6z - s6 * y6z) - s5 * z6z
    p4x = p5x - d5 * (-s6 * x6x - c6 * y6x)
    p4y = p5y - d5 * (-s6 * x6y - c6 * y6y)
    p4z = p5z - d5 * (-s6 * x6z - c6 * y6z)
    c1b, s1b = c1[:, None], s1[:, None]
    px = c1b * p4x + s1b * p4y
    py = p4z - d1
    t234 = np.arctan2(x4z, c1b * x4x + s1b * x4y)

    # Planar 3R: theta3 (elbow branch, axis 2), then theta2 and theta4.
    c3 = (px * px + py * py - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)
    ok3 = np.abs(c3) <= 1.0 + _REACH_EPS
    c3 = np.clip(c3, -1.0, 1.0)
    s3abs = np.sqrt(1.0 - c3 * c3)
    s3 = np.stack([s3abs, -s3abs], axis=2)  # (2, 2, 2, n)
    c3 = c3[:, :, None]
    t3 = np.arctan2(s3, c3)
    t2 = np.arctan2(py, px)[:, :, None] - np.arctan2(a3 * s3, a2 + a3 * c3)
    t4 = t234[:, :, None] - t2 - t3

    shape = (2, 2, 2, n)
    q = np.stack(
        [
            np.broadcast_to(t1[:, None, None], shape),
            np.broadcast_to(t2, shape),
            t3,
            t4,
            np.broadcast_to(np.arctan2(s5, c5)[:, :, None], shape),
            np.broadcast_to(t6[:, :, None], shape),
        ],
        axis=-1,
    )
    q = wrap_deg(np.degrees(q))
    valid = np.broadcast_to(ok1 & ok5[:, None, None] & ok3[:, :, None], shape)
    q[~valid] = np.nan

    def flat(a: np.ndarray) -> np.ndarray:
        return np.moveaxis(np.broadcast_to(a, shape), -1, 0).reshape(*batch, 8)

    return IKSolutions(
        q=np.moveaxis(q, 3, 0).reshape(*batch, 8, 6),
        valid=flat(valid),
        wrist_singular=flat((s5abs < singular_tol)[:, None, None]) & flat(valid),
        elbow_singular=flat((s3abs < singular_tol)[:, :, None]) & flat(valid),
        shoulder_singular=flat(horiz < singular_tol * model.reach_mm) & flat(valid),
    )


# ---------------------------------------------------------------------------------------------
# Choosing a solution

_OK, _UNREACHABLE, _LIMITS, _SINGULAR = 0, 1, 2, 3
_LIMIT_EPS_DEG = 1e-9


def equivalent_within_limits(
    q_deg: np.ndarray, q_ref_deg: np.ndarray, limits_deg: np.ndarray
) -> np.ndarray:
    """The angle equal to q modulo 360 within limits and nearest q_ref, per joint; NaN if none.

    Shapes broadcast: q (..., 6), q_ref (..., 6), limits (6, 2) deg. The nearest equivalent
    within limits is always within 360 deg of q_ref, so three candidates suffice.
    """
    q = np.asarray(q_deg, dtype=float)
    ref = np.asarray(q_ref_deg, dtype=float)
    lim = np.asarray(limits_deg, dtype=float)
    k0 = np.round((ref - q) / 360.0)
    cand = (q + 360.0 * k0)[..., None] + np.array([-360.0, 0.0, 360.0])
    lo, hi = lim[:, 0, None] - _LIMIT_EPS_DEG, lim[:, 1, None] + _LIMIT_EPS_DEG
    inside = (cand >= lo) & (cand <= hi)
    dist = np.where(inside, np.abs(cand - ref[..., None]), np.inf)
    best = np.argmin(dist, axis=-1)
    out = np.take_along_axis(cand, best[..., None], axis=-1)[..., 0]
    out = np.clip(out, lim[:, 0], lim[:, 1])
    return np.where(np.isfinite(np.min(dist, axis=-1)), out, np.nan)


def _select(
    sols: IKSolutions,
    q_current: np.ndarray,
    limits: np.ndarray,
    weights: np.ndarray,
    allow_singular: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest admissible branch per pose: q (N, 6) (NaN if none) and a reason code (N,)."""
    q = sols.q.reshape(-1, 8, 6)
    n = q.shape[0]
    cur = np.broadcast_to(np.asarray(q_current, dtype=float), (n, 6))
    valid = sols.valid.reshape(n, 8)
    singular = sols.singular.reshape(n, 8)
    cand = equivalent_within_limits(q, cur[:, None, :], limits)
    in_limits = valid & np.isfinite(cand).all(axis=-1)
    usable = in_limits if allow_singular else in_limits & ~singular
    cost = np.where(usable, np.sum(weights * (cand - cur[:, None, :]) ** 2, axis=-1), np.inf)
    best = np.argmin(cost, axis=1)
    ok = usable.any(axis=1)
    out = np.where(ok[:, None], cand[np.arange(n), best], np.nan)
    code = np.full(n, _OK)
    code[~ok & in_limits.any(axis=1)] = _SINGULAR
    code[~ok & ~in_limits.any(axis=1) & valid.any(axis=1)] = _LIMITS
    code[~valid.any(axis=1)] = _UNREACHABLE
    return out, code


def nearest_solutions(
    model: URModel,
    T: np.ndarray,
    q_current: np.ndarray,
    limits_deg: np.ndarray | None = None,
    *,
    tool: np.ndarray | None = None,
    weights: np.ndarray | None = None,
    allow_singular: bool = True,
    singular_tol: float = 1e-6,
) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised `nearest_solution`: q (..., 6) deg (NaN where none) and ok (...) per pose.

    q_current is (6,) or (..., 6) matching the poses (..., 4, 4).
    """
    Tf, batch = as_batch(T, (4, 4), "T")
    cur = np.broadcast_to(np.asarray(q_current, dtype=float), (*batch, 6)).reshape(-1, 6)
    lim = model.limits if limits_deg is None else np.asarray(limits_deg, dtype=float)
    w = np.ones(6) if weights is None else np.asarray(weights, dtype=float)
    sols = inverse(model, Tf, tool=tool, q6_hint_deg=cur[:, 5], singular_tol=singular_tol)
    q, code = _select(sols, cur, lim, w, allow_singular)
    return q.reshape(*batch, 6), (code == _OK).reshape(batch)


def nearest_solution(
    model: URModel,
    T: np.ndarray,
    q_current: np.ndarray,
    limits_deg: np.ndarray | None = None,
    *,
    tool: np.ndarray | None = None,
    weights: np.ndarray | None = None,
    allow_singular: bool = True,
    singular_tol: float = 1e-6,
) -> np.ndarray:
    """The joint vector (6,) deg reaching pose T (4, 4) nearest q_current within limits.

    Every branch is moved by multiples of 360 deg to the equivalent angle within limits
    (default: the model's) nearest the current joints; the branch with the smallest
    weighted squared joint distance wins. At a wrist singularity theta6 stays at its current
    value. Raises UnreachableError, JointLimitError, or SingularPoseError (only when
    `allow_singular` is False and every admissible branch is singular).
    """
    Tm = np.asarray(T, dtype=float)
    if Tm.shape != (4, 4):
        raise ValueError(f"nearest_solution takes one pose (4, 4), got {Tm.shape}")
    cur = np.asarray(q_current, dtype=float)
    if cur.shape != (6,):
        raise ValueError(f"q_current must have shape (6,), got {cur.shape}")
    lim = model.limits if limits_deg is None else np.asarray(limits_deg, dtype=float)
    w = np.ones(6) if weights is None else np.asarray(weights, dtype=float)
    sols = inverse(model, Tm[None], tool=tool, q6_hint_deg=cur[5], singular_tol=singular_tol)
    q, code = _select(sols, cur, lim, w, allow_singular)
    if code[0] == _OK:
        return q[0]
    xyz = np.array2string(
        (Tm @ (invert_pose(tool) if tool is not None else np.eye(4)))[:3, 3],
        precision=1,
        separator=", ",
    )
    if code[0] == _UNREACHABLE:
        raise UnreachableError(
            f"flange pose at {xyz} mm in the {model.name} base frame is out of reach: "
            f"check the target and the robot base pose (reach about {model.reach_mm:.0f} mm "
            "from the shoulder)"
        )
    if code[0] == _LIMITS:
        raise JointLimitError(
            f"flange pose at {xyz} mm is reachable by the {model.name} only beyond its joint "
            f"limits {model.limits.tolist() if limits_deg is None else lim.tolist()} deg; "
            "choose another tool orientation or widen the limits"
        )
    raise SingularPoseError(
        f"flange pose at {xyz} mm is at a singular configuration of the {model.name}; "
        "tilt the tool or move the target slightly"
    )
