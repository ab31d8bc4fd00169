"""The heading's consistency with the field it follows: a classical filter's heading σ widens where its heading and
its own field disagree by more than the field's σ explains (ROS-free).

Madgwick, Mahony and VQF pull their heading toward the field they are given, at their own gain; the heading σ they
report is the field heading's own (:data:`~riann_ros.defaults.MAG_HEADING_SD_DEG`) with the calibration's share
(:mod:`.classical`): the σ of a heading that has converged onto a right field. Where it has not — a heading still
converging from a wrong start, turned by a late field, set anew by a realign, or held by the gyro while the filter
rejects a disturbed field — the filter's heading and the field disagree, and the disagreement is the measurement of
that error the filter already has. The innovation ``ν = ψ_field − ψ_filter`` (the field's heading at the filter's
attitude, :func:`~riann_ros.magcal.heading.field_heading`) has, with independent errors,
``E[ν²] = σ_ψ² + σ_f²`` (``σ_f`` the field heading's σ at that row): so its mean square over the last
:data:`TAU_S` estimates the heading's error variance, ``σ_seen² = max(0, ⟨ν²⟩ − σ_f²)``, which the reported σ adds in
quadrature (covariance matching, Mehra 1970). :data:`TAU_S` is the time scale on which such an error appears (a
turn, a realign), short against the filters' field time constants (VQF's ``tau_mag`` 9 s), so the σ follows an
error while it lasts; at 50–500 samples per second the mean square's own scatter is small. A field that is wrong
where the heading is right (a magnet the filter rejects) widens the σ too: cautious, never confident. The filter's
outputs never change.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from riann_ros.magcal.heading import field_heading

#: s; the time constant of the innovation's mean square (module docstring)
TAU_S = 1.0


class HeadingConsistency:
    """The innovation's mean square (module docstring), per row in plain floats (the node's call is a block of
    one); a reset starts it anew."""

    def __init__(self) -> None:
        self.mean_square: float | None = None  # rad²; None: no field yet

    def run(self, q: NDArray[np.float64], field: list, dt: NDArray[np.float64],
            field_sd: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n,) rad: the heading σ the disagreement shows at each row (``σ_seen``; the last value held where a row
        has no field). ``q`` the filter's outputs (sensor → ENU), ``field`` its field per row (a zero row or None: no
        field), ``dt`` the steps (s), ``field_sd`` the field heading's σ per row (rad)."""
        n = len(q)
        out = np.zeros(n)
        ms = self.mean_square
        sd2 = (np.asarray(field_sd, dtype=float) ** 2).tolist() if n else []
        for i, (qi, m, h) in enumerate(zip(q.tolist(), field, np.asarray(dt, dtype=float).tolist(), strict=True)):
            psi = None if m is None else field_heading(tuple(qi), tuple(m))  # (None for a zero row too)
            if psi is not None:
                nu2 = psi * psi
                ms = nu2 if ms is None else ms + min(h / TAU_S, 1.0) * (nu2 - ms)
            if ms is not None:
                out[i] = math.sqrt(max(0.0, ms - sd2[i]))
        self.mean_square = ms
        return out
