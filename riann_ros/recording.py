"""The in-memory form of one IMU recording with its reference, shared by readers, bags and tools."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from riann_ros import defaults


@dataclass
class Recording:
    """One IMU sequence with optional ground truth.

    ``stamps_ns``: (N,) int64 sample times in nanoseconds, strictly increasing.
    ``acc``: (N, 3) float64 m/s². ``gyr``: (N, 3) float64 rad/s.
    ``quat_ref``: (N, 4) float64 w, x, y, z sensor-to-world (ENU) reference; NaN rows where missing;
    ``None`` when the recording has no reference at all.
    ``score_mask``: (N,) bool, samples to be scored (e.g. BROAD's ``movement``); all True when unknown.
    ``name``: sequence name; ``dataset``: dataset/group name; ``source``: citation or origin;
    ``frame_id``: sensor frame; ``meta``: free-form extra metadata (str → str).
    ``mag``: (N, 3) float64 magnetic field in tesla (REP-145), sensor frame, the magnetometer sample
    stamped like the IMU sample; NaN rows where there is none; ``None`` when the recording has no
    magnetometer.
    """

    stamps_ns: NDArray[np.int64]
    acc: NDArray[np.float64]
    gyr: NDArray[np.float64]
    quat_ref: NDArray[np.float64] | None = None
    score_mask: NDArray[np.bool_] = None  # type: ignore[assignment]  # None: all scored (__post_init__)
    name: str = "sequence"
    dataset: str = ""
    source: str = ""
    frame_id: str = defaults.IMU_FRAME
    meta: dict[str, str] = field(default_factory=dict)
    mag: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        n = len(self.stamps_ns)
        self.stamps_ns = np.asarray(self.stamps_ns, dtype=np.int64)
        self.acc = np.asarray(self.acc, dtype=np.float64).reshape(n, 3)
        self.gyr = np.asarray(self.gyr, dtype=np.float64).reshape(n, 3)
        if self.quat_ref is not None:
            self.quat_ref = np.asarray(self.quat_ref, dtype=np.float64).reshape(n, 4)
        if self.mag is not None:
            self.mag = np.asarray(self.mag, dtype=np.float64).reshape(n, 3)
        if self.score_mask is None:
            self.score_mask = np.ones(n, dtype=bool)
        self.score_mask = np.asarray(self.score_mask, dtype=bool).reshape(n)

    def __len__(self) -> int:
        return len(self.stamps_ns)

    @property
    def t(self) -> NDArray[np.float64]:
        """Sample times in seconds relative to the first sample."""
        return (self.stamps_ns - self.stamps_ns[0]) * 1e-9

    @property
    def dt(self) -> NDArray[np.float64]:
        """Per-sample time step in seconds; the first sample gets the median step."""
        d = np.diff(self.stamps_ns) * 1e-9
        first = float(np.median(d)) if len(d) else defaults.FALLBACK_DT_S
        return np.concatenate([[first], d])

    @property
    def rate_hz(self) -> float:
        return 1.0 / float(np.median(np.diff(self.stamps_ns) * 1e-9)) if len(self) > 1 else float("nan")

    def slice(self, start: int, stop: int | None = None) -> Recording:
        """A copy of samples ``start:stop``."""
        s = slice(start, stop)
        return Recording(
            stamps_ns=self.stamps_ns[s].copy(),
            acc=self.acc[s].copy(),
            gyr=self.gyr[s].copy(),
            quat_ref=None if self.quat_ref is None else self.quat_ref[s].copy(),
            score_mask=self.score_mask[s].copy(),
            name=self.name,
            dataset=self.dataset,
            source=self.source,
            frame_id=self.frame_id,
            meta=dict(self.meta),
            mag=None if self.mag is None else self.mag[s].copy(),
        )
