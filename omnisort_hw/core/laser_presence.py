"""Is there a laser line in the image at all? "No laser here" as a result, not as a handful of
phantom points.

A laser plane meets the scene along a curve that crosses it: the image of a laser line is a
thin curve many times longer than it is wide. What the stripe extractor finds where no line
is (`core.laser_stripe`) is not: measured on real photographs of the development sets
(docs/real_light.md), the phantoms of laser-off or unfocused photographs are

- **spots**: a red LED or a small coloured mark, found along both scan directions as a cross
  of 10 points 12 px across (its extent is its width);
- **blobs**: a defocused or diffuse patch of laser light, whose speckle gives chains up to
  150 px long whose points scatter 1.5 to 2.5 px RMS about their local line (points of a
  line scatter by their sub-pixel noise: on the photographs with a line, the thinnest chain
  32 px or longer of each is 0.0 to 0.63 px RMS, median 0.04 px).

So an image shows a laser line when one of its chains is a **line**: at least
`MIN_LINE_SCANS` scan lines long (the length the extractor already asks of a faint stripe's
chain, 16 scan lines: 32 px at 1280x960, 64 px at 1920) and thin, its points within
`MAX_LINE_SCATTER_PX` RMS of their local line (1 px: between a line's sub-pixel scatter and a
blob's width). An image with no line gives no points; one with a line keeps every chain the
extractor kept, short pieces on small objects included.

Arrays in, arrays out: (N, 2) points and their (N,) chain labels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from omnisort_hw.core.records import LaserLineReply

MIN_LINE_SCANS = 16  # scan lines a line spans (core.laser_stripe._LONG_CHAIN)
MAX_LINE_SCATTER_PX = 1.0  # RMS of a line's points about their local line
_NEIGHBOURS = 7  # points of a chain in each local line fit


@dataclass(frozen=True)
class LinePresence:
    """Whether the points hold a laser line, and what the longest thin chain was."""

    present: bool
    longest_line_px: float  # the longest chain that is thin (0 without one)
    min_line_px: float  # what a line needs
    chains: int  # chains the extractor kept
    spots: int  # of which shorter than a line
    blobs: int  # of which long enough but not thin
    points: int  # the points those chains held (all dropped when no line is present)

    def reason(self) -> str:
        """Why no line was seen, for warnings and verdicts ('' when one was)."""
        if self.present:
            return ""
        if self.chains == 0:
            return "no laser line in the image (no stripe candidates)"
        return (
            f"no laser line in the image: {self.points} point(s) in {self.chains} piece(s), "
            f"{self.spots} shorter than a line's {self.min_line_px:.0f} px and {self.blobs} "
            "not thin "
            f"(points more than {MAX_LINE_SCATTER_PX:g} px RMS off their local line), the "
            "light of a spot, a coloured mark or a defocused patch, not of a line"
        )

    def to_dict(self) -> LaserLineReply:
        return LaserLineReply(
            present=self.present,
            longest_line_px=round(self.longest_line_px, 1),
            min_line_px=round(self.min_line_px, 1),
            chains=self.chains,
            spots=self.spots,
            blobs=self.blobs,
            points=self.points,
        )


def chain_shapes(
    points: np.ndarray, chains: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per chain: (labels (K,), length along its principal axis (K,) px, median RMS (K,) px of
    its points about the line through each point's `_NEIGHBOURS` nearest of the same chain;
    inf for a chain with fewer points)."""
    pts = np.asarray(points, float).reshape(-1, 2)
    lab = np.asarray(chains, np.int64).reshape(-1)
    labels, idx, count = np.unique(lab, return_inverse=True, return_counts=True)
    k = len(labels)
    if k == 0:
        return labels, np.zeros(0), np.zeros(0)
    mean = np.stack([np.bincount(idx, pts[:, j], k) for j in (0, 1)], axis=1) / count[:, None]
    d = pts - mean[idx]
    sxx = np.bincount(idx, d[:, 0] ** 2, k)
    syy = np.bincount(idx, d[:, 1] ** 2, k)
    sxy = np.bincount(idx, d[:, 0] * d[:, 1], k)
    angle = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # the principal axis of each chain
    along = d[:, 0] * np.cos(angle)[idx] + d[:, 1] * np.sin(angle)[idx]
    hi = np.full(k, -np.inf)
    lo = np.full(k, np.inf)
    np.maximum.at(hi, idx, along)
    np.minimum.at(lo, idx, along)
    length = hi - lo
    scatter = np.full(k, np.inf)
    big = count >= _NEIGHBOURS
    if big.any():
        from scipy.spatial import cKDTree

        sel = big[idx]
        q = pts[sel]
        # Chains kept apart by an offset far beyond any image: neighbours stay in their chain.
        key = np.column_stack([q[:, 0] + 1e7 * idx[sel], q[:, 1]])
        _, nn = cKDTree(key).query(key, _NEIGHBOURS)
        nb = q[nn] - q[nn].mean(axis=1, keepdims=True)  # (M, k, 2)
        c = np.einsum("mki,mkj->mij", nb, nb) / _NEIGHBOURS
        tr, det = c[:, 0, 0] + c[:, 1, 1], c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] ** 2
        small = 0.5 * tr - np.sqrt(np.maximum(0.25 * tr**2 - det, 0.0))  # least eigenvalue
        rms = np.sqrt(np.maximum(small, 0.0))
        sub = idx[sel]
        order = np.lexsort((rms, sub))  # each chain's values in order: its median by rank
        starts = np.searchsorted(sub[order], np.flatnonzero(big))
        n_big = count[big]
        lo_i, hi_i = starts + (n_big - 1) // 2, starts + n_big // 2
        scatter[big] = 0.5 * (rms[order][lo_i] + rms[order][hi_i])
    return labels, length, scatter


def line_presence(points: np.ndarray, chains: np.ndarray, stride: int) -> LinePresence:
    """Whether the extractor's (N, 2) points with their (N,) chain labels, found on scan lines
    `stride` px apart, hold a laser line (module docstring)."""
    need = float(MIN_LINE_SCANS * stride)
    _, length, scatter = chain_shapes(points, chains)
    long_enough = length >= need
    thin = scatter <= MAX_LINE_SCATTER_PX
    lines = long_enough & thin
    return LinePresence(
        bool(lines.any()),
        float(length[lines].max()) if lines.any() else 0.0,
        need,
        len(length),
        int((~long_enough).sum()),
        int((long_enough & ~thin).sum()),
        int(np.asarray(points).reshape(-1, 2).shape[0]),
    )
