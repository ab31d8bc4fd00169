"""Resampling of recordings to another rate, as in the paper (ROS-free).

IMU signals: FFT-based (``scipy.signal.resample``), acc and gyr independently. ``n1`` output samples
span the ``n0`` input samples' period, so output sample ``k`` is the signal at input index
``k · n0 / n1``: its stamp is the input's time at that index, and the rate is ``rate_hz`` only to
within ``1 / n1`` (stamps ``k / rate_hz`` would drift from the samples, by 14 ms over a 3-minute
BROAD trial at 25 Hz). The reference quaternion: slerp between the two neighbouring samples at that
index (NaN where either neighbour is missing); the score mask: nearest sample.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import resample as fft_resample

from riann_ros import quaternion as quat
from riann_ros.constants import NS_PER_S
from riann_ros.recording import Recording


def resample_recording(rec: Recording, rate_hz: float) -> Recording:
    """``rec`` resampled to ``rate_hz`` over the same time span (uniform stamps from the first one)."""
    if rate_hz <= 0:
        raise ValueError(f"rate must be positive, got {rate_hz}")
    f0 = rec.rate_hz
    n0 = len(rec)
    n1 = max(2, round(n0 * rate_hz / f0))
    acc = fft_resample(rec.acc, n1, axis=0)
    gyr = fft_resample(rec.gyr, n1, axis=0)
    pos = np.arange(n1) * (n0 / n1)  # input index of each output sample
    # stamps: the input's times at those indices (linear between its stamps, one step beyond the last)
    st = rec.stamps_ns.astype(np.float64)
    step = (st[-1] - st[0]) / (n0 - 1) if n0 > 1 else NS_PER_S / rate_hz
    t1 = np.interp(pos, np.arange(n0), st - st[0], right=np.nan)
    beyond = ~np.isfinite(t1)
    t1[beyond] = st[-1] - st[0] + (pos[beyond] - (n0 - 1)) * step
    pos = np.clip(pos, 0, n0 - 1)
    i0 = np.minimum(np.floor(pos).astype(int), n0 - 2)
    s = pos - i0
    ref = None
    if rec.quat_ref is not None:
        a, b = rec.quat_ref[i0], rec.quat_ref[i0 + 1]
        ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
        ref = np.full((n1, 4), np.nan)
        ref[ok] = quat.slerp(a[ok], b[ok], s[ok])
    mask = rec.score_mask[np.clip(np.round(pos).astype(int), 0, n0 - 1)]
    mag = None
    if rec.mag is not None:  # FFT like acc when complete, else the latest field sample (holes stay holes)
        mag = fft_resample(rec.mag, n1, axis=0) if np.isfinite(rec.mag).all() else rec.mag[np.floor(pos).astype(int)]
    stamps = rec.stamps_ns[0] + np.round(t1).astype(np.int64)
    meta = dict(rec.meta, resampled_from_hz=repr(f0), sampling_rate=repr(rate_hz))
    return Recording(stamps_ns=stamps, acc=acc, gyr=gyr, quat_ref=ref, score_mask=mask, name=rec.name,
                     dataset=rec.dataset, source=rec.source, frame_id=rec.frame_id, meta=meta, mag=mag)
