"""Attitude error metrics (paper eq. 3) and their aggregation, ROS-free."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from riann_ros.quaternion import heading_error, inclination_error, total_error

__all__ = ["heading_error", "inclination_error", "rmse_deg", "total_error"]


def rmse_deg(q_true: ArrayLike, q_est: ArrayLike, mask: ArrayLike | None = None) -> float:
    """RMSE of e_α in degrees over samples in ``mask`` with a reference present (NaN rows skipped).

    Raises ``ValueError`` when no sample is left to score.
    """
    e = inclination_error(q_true, q_est)
    valid = np.isfinite(e)
    if mask is not None:
        valid &= np.asarray(mask, dtype=bool)
    if not valid.any():
        raise ValueError("no scored samples (score mask ∩ reference present is empty)")
    return float(np.degrees(np.sqrt(np.mean(e[valid] ** 2))))
