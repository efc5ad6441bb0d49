"""How many residuals of a fit are worth one independent one, from their own correlation.

A feature measured at every pixel of an edge (a target's border, a cube's outline) gives
residuals that share their pixels' quantisation and threshold errors with their neighbours;
a covariance that counts them as independent is too small by this factor. Used by the
one-image calibration's line blocks and by the cube outline fit.
"""

from __future__ import annotations

import numpy as np


def correlation_inflation(residuals: np.ndarray, max_lag: int = 10) -> float:
    """Variance inflation 1 + 2 sum(rho_k) of an average of residuals ordered along a line,
    from their autocorrelation up to the first lag within the noise of an estimate from n
    points (2 / sqrt(n)); 1 for independent points, about the number of points sharing each
    pixel otherwise."""
    r = np.asarray(residuals, float) - np.mean(residuals)
    n = r.size
    denom = float(r @ r)
    if n < 8 or denom <= 0:
        return 1.0
    total = 0.0
    for k in range(1, min(max_lag, n // 4) + 1):
        rho = float(r[:-k] @ r[k:]) / denom
        if rho <= 2.0 / np.sqrt(n):  # indistinguishable from no correlation
            break
        total += rho
    return float(np.clip(1.0 + 2.0 * total, 1.0, 10.0))
