"""What every estimator shares: the lost-tracking covariance and the RANSAC and refinement
settings."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
LOST_VARIANCE = 9999.0
_CONFIDENCE = 0.99
_HUBER_PX = 1.0  # px: robust kernel width of the refinement
_REFINE_STEPS = 10  # Gauss-Newton steps per refinement


def huge_covariance() -> F64:
    """The covariance published for a failed registration or lost tracking (6 × 6)."""
    return np.eye(6) * LOST_VARIANCE
