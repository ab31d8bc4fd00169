"""The offline calibration: a robust batch fit over all windows of a whole recording (ROS-free).

The same windows and the same linear constraint as online (:mod:`.windows`, :mod:`.model`), solved at once with
``scipy.optimize.least_squares``: each window's residual whitened by its noise, the prior as pseudo-residuals, and
a robust loss (Cauchy, scale 2 × the residuals' robust spread), started from the online calibration run over the
same recording: the windows that fail the online gate against its final estimate are left out (disturbed, or from
another magnetic situation: BROAD trial 33 has a magnet attached for 55 of its 125 s of motion, more windows than
the rest; the fit, like the online calibration, is the situation at the recording's end). At the robust solution the
weighted normal equations are solved once more with the online rule (only directions the windows observe at least
as well as the prior move, :func:`~.model.posterior`), their information divided by the variance of unit weight (when
above 1) and by how many windows share each one's noise, measured from their residuals (:func:`shared_noise`); for
the covariance it is divided by the variance of unit weight and by the windows' overlap (:func:`windows_of`, the
most that can share a reading or a gyro path), so it is not overstated. The misalignment's prior (1°) is tight: a
non-symmetric soft iron of a few degrees is observed about as well as the prior knows it when the information is
divided by the overlap (~100 windows cover each stretch of rich rotation), only a few windows share one another's
noise, and a misalignment held at the prior biases the hard iron by about a µT.

Why not the ``magyc`` package (MAGYC, Rodríguez-Martínez et al. 2024): its 1.0.0 wheel requires ``numpy < 2``
(this project pins numpy 2.4) and pulls gtsam, jax, jaxlib, navlib, lcm and pyproj; its batch least-squares
variant (``magyc_ls``) differentiates the field numerically per sample (noise- and latency-sensitive), fixes the
soft iron symmetric with unit determinant, and returns no covariance. The model here is the one the online
calibration runs, so offline and online estimates are the same quantity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from riann_ros import quaternion as quat
from riann_ros.magcal.input import plausible
from riann_ros.magcal.model import Array, CalModel, heading_sd_bound, posterior
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import (
    CALIBRATED,
    CALIBRATED_SD_RAD,
    CONVERGING,
    DELAY_SD_S,
    GATE_CHI2,
    MAX_STEP_S,
    STATE_HEADINGS,
    UNCALIBRATED,
    UT,
    WINDOW_ANGLE_RAD,
    WINDOW_MAX_S,
    WINDOW_MIN_ANGLE_RAD,
    MagCalibration,
    MagCalPrior,
    SoftIronModel,
)
from riann_ros.magcal.windows import WindowSet

ROBUST_SCALE = 2.0  # the Cauchy loss bends at this many robust standard deviations of the whitened residuals
MAD_TO_SD = 1.4826  # a normal distribution's standard deviation per median absolute deviation
MAX_WINDOWS = 20_000  # windows of one fit at most (the stacked system is 3 rows per window: a few MB)
#: the autocorrelation's sum runs over lags up to this many times its running value (Sokal's automatic window: long
#: enough to hold the correlation, short enough that the estimate's noise stays small)
CORRELATION_WINDOW = 5.0


@dataclass(frozen=True)
class OfflineFit:
    """A batch fit: the calibration, the windows' residual (RMS, µT, at the solution), the calibrated field's
    norm (median and standard deviation, µT: the sphere's radius and thickness), the windows used, those down-weighted
    below half by the robust loss (outliers), and the variance of unit weight."""

    calibration: MagCalibration
    residual_rms_ut: float
    field_norm_ut: float
    field_norm_sd_ut: float
    windows: int
    outliers: int  # windows left out (another magnetic situation) or down-weighted below half
    unit_weight: float


def _attitudes(gyr: Array, dt: Array) -> Array:
    """The integrated gyro attitude (N, 4) from the first sample (``q_k = q_{k−1} ⊗ exp(ω_k dt_k)``)."""
    inc = quat.from_rotvec(gyr * dt[:, None])
    out = np.empty_like(inc)
    w, x, y, z = 1.0, 0.0, 0.0, 0.0
    for i, (bw, bx, by, bz) in enumerate(inc.tolist()):
        w, x, y, z = (w * bw - x * bx - y * by - z * bz, w * bx + x * bw + y * bz - z * by,
                      w * by - x * bz + y * bw + z * bx, w * bz + x * by - y * bx + z * bw)
        out[i] = (w, x, y, z)
    return quat.normalize(out)


def _delayed(q: Array, t: Array, delay_s: float) -> Array:
    """The attitude at ``t − delay_s`` per sample (normalised lerp between samples; the first before it)."""
    if delay_s <= 0.0:
        return q
    k = np.clip(np.searchsorted(t, t - delay_s, side="right") - 1, 0, len(t) - 1)
    k1 = np.minimum(k + 1, len(t) - 1)
    span = t[k1] - t[k]
    f = np.clip(np.where(span > 0, (t - delay_s - t[k]) / np.where(span > 0, span, 1.0), 0.0), 0.0, 1.0)
    b = np.where((np.sum(q[k] * q[k1], axis=1) < 0)[:, None], -q[k1], q[k1])
    return quat.normalize(q[k] + f[:, None] * (b - q[k]))


def windows_of(gyr: ArrayLike, dt: ArrayLike, mag_t: ArrayLike, delay_s: float = 0.0,
               max_windows: int = MAX_WINDOWS) -> tuple[WindowSet, float]:
    """All windows of a recording, one starting at every reading (every few when there are more than
    ``max_windows``), each closed once it has turned 45°, or after :data:`~.records.WINDOW_MAX_S` if it turned 15°
    (the online :class:`~.windows.Windower` also closes one at a swing's end: here a window starts at every reading,
    so the swing's end starts windows of its own); and their overlap: how many of them
    share each stretch of rotation (the factor their information is overstated by, as their noises are not
    independent). ``gyr`` (N, 3) bias-corrected rad/s, ``dt`` (N,) s (a step outside (0, MAX_STEP_S] breaks the
    windows across it), ``mag_t`` (N, 3) raw T (NaN rows: none)."""
    g = np.asarray(gyr, dtype=float).reshape(-1, 3)
    d = np.asarray(dt, dtype=float).reshape(-1)
    m = np.asarray(mag_t, dtype=float).reshape(-1, 3)
    n = len(g)
    ok = plausible(m)
    good_dt = (d > 0.0) & (d <= MAX_STEP_S)
    seg = np.cumsum(~good_dt)
    t = np.cumsum(np.where(good_dt, d, 0.0))
    q = _attitudes(g, np.where(good_dt, d, 0.0))
    qd = _delayed(q, t, delay_s)
    rate = np.linalg.norm(g, axis=1)
    starts = np.flatnonzero(ok & good_dt)
    stride = max(1, -(-len(starts) // max_windows))
    starts = starts[::stride]
    ends = np.full(len(starts), -1)
    active = np.ones(len(starts), dtype=bool)
    cos_half, cos_min = math.cos(0.5 * WINDOW_ANGLE_RAD), math.cos(0.5 * WINDOW_MIN_ANGLE_RAD)
    lag = 1
    while active.any() and lag < n:
        j = starts[active]
        k = j + lag
        inside = (k < n)
        kk = np.minimum(k, n - 1)
        inside &= seg[kk] == seg[j]
        c = np.abs(np.sum(q[j] * q[kk], axis=1))
        el = t[kk] - t[j]
        turned = c <= cos_half
        timed = el >= WINDOW_MAX_S
        close = inside & ok[kk] & (turned | (timed & (c <= cos_min)))
        drop = ~inside | (inside & ok[kk] & timed & ~close) | (el >= WINDOW_MAX_S + 1.0)
        idx = np.flatnonzero(active)
        ends[idx[close]] = kk[close]
        active[idx[close | drop]] = False
        lag += 1
    keep = ends >= 0
    j, k = starts[keep], ends[keep]
    rot = quat.normalize(quat.multiply(quat.conjugate(qd[j]), qd[k]))
    rot = np.where(rot[:, :1] < 0, -rot, rot)
    ws = WindowSet(m[j] / UT, m[k] / UT, rot, t[k] - t[j], 2.0 * np.arccos(np.clip(rot[:, 0], -1.0, 1.0)),
                   rate[j], rate[k], np.full(len(j), DELAY_SD_S))
    span = np.zeros(n + 1)
    np.add.at(span, j, 1.0)
    np.add.at(span, k, -1.0)
    cover = np.cumsum(span)[:n]
    overlap = float(np.mean(cover[cover > 0])) if np.any(cover > 0) else 1.0
    return ws, max(overlap, 1.0)


def _whitened(model: CalModel, ws: WindowSet, theta: Array) -> tuple[Array, Array]:
    """The stacked whitened rows ``(J (3W, n), r₀ (3W,))`` with each window's σ at ``theta``."""
    j, r0 = model.rows(ws)
    s = 1.0 / np.sqrt(model.window_var(ws, model.soft_iron(theta), theta[model.p:]))
    return (j * s[:, None, None]).reshape(-1, model.n), (r0 * s[:, None]).reshape(-1)


def _consistent(model: CalModel, ws: WindowSet, theta: Array, cov: Array) -> NDArray[np.bool_]:
    """The windows whose innovation against ``(θ, cov)`` passes the online gate."""
    j, r0 = model.rows(ws)
    r = r0 + j @ theta
    var = model.window_var(ws, model.soft_iron(theta), theta[model.p:])
    s = var[:, None, None] * np.eye(3) + j @ cov @ np.swapaxes(j, 1, 2)
    d2 = np.einsum("wi,wi->w", r, np.linalg.solve(s, r[..., None])[..., 0])
    return d2 <= GATE_CHI2


def shared_noise(z: Array, overlap: float) -> float:
    """How many windows share each window's noise: the integrated autocorrelation time of the windows' whitened
    residuals ``z`` (3 per window) in the order the windows start, summed over lags up to
    :data:`CORRELATION_WINDOW` times its running value; between 1 and ``overlap`` (windows that share no stretch of
    rotation share no reading and no gyro path: independent, as online)."""
    x = z.reshape(-1, 3)
    x = x - x.mean(axis=0)
    w = len(x)
    var = float(np.sum(x * x))
    if w < 2 or var <= 0.0:
        return 1.0
    size = 1 << (2 * w - 1).bit_length()
    f = np.fft.rfft(x, n=size, axis=0)
    acf = np.fft.irfft(np.sum(f * np.conj(f), axis=1), n=size)[:w] / var  # Σ over lag-l pairs, per component
    tau = 2.0 * np.cumsum(acf) - 1.0  # 1 + 2 Σ_{l=1..L} ρ_l
    lag = np.arange(w)
    inside = lag < CORRELATION_WINDOW * tau
    end = int(np.argmin(inside)) if not inside.all() else w - 1
    return float(min(max(tau[end], 1.0), max(overlap, 1.0)))


def fit_windows(ws: WindowSet, overlap: float = 1.0, prior: MagCalPrior | None = None,
                soft_iron_model: SoftIronModel = "full", start: tuple[Array, Array] | None = None
                ) -> tuple[CalModel, Array, Array, Array, int]:
    """``(model, θ, covariance, whitened residuals, outliers)`` of the robust batch fit (module docstring);
    ``overlap`` (≥ 1) scales the covariance for windows that share their noise (:func:`windows_of`); ``start``:
    ``(θ, covariance)`` to start from (the online estimate at the recording's end): windows that fail its gate are
    left out (another magnetic situation: a magnet attached for a while), else the ordinary least squares."""
    prior = prior or MagCalPrior()
    model = CalModel(soft_iron_model, np.asarray(prior.soft_iron).reshape(3, 3))
    lam0, theta0 = model.prior(prior)
    l0 = np.linalg.cholesky(lam0).T  # ‖l0 (θ − θ₀)‖² = (θ − θ₀)ᵀ Λ₀ (θ − θ₀)
    left_out = 0
    if start is not None and len(ws):
        keep = _consistent(model, ws, *start)
        left_out = int(np.count_nonzero(~keep))
        ws = WindowSet(*(getattr(ws, f)[keep] for f in ws.__dataclass_fields__))
    if not len(ws):
        return model, theta0, np.linalg.inv(lam0), np.zeros(0), left_out
    if start is not None:
        theta = start[0]
    else:
        j, r0 = _whitened(model, ws, theta0)
        theta = np.linalg.lstsq(np.vstack([j, l0]), np.r_[-r0, l0 @ theta0], rcond=None)[0]
    j, r0 = _whitened(model, ws, theta)  # the windows' σ at the start
    z = r0 + j @ theta
    spread = max(MAD_TO_SD * float(np.median(np.abs(z - np.median(z)))), 1e-9)
    fs = ROBUST_SCALE * spread

    def resid(x: Array) -> Array:
        return np.r_[r0 + j @ x, l0 @ (x - theta0)]

    def jac(_: Array) -> Array:
        return np.vstack([j, l0])

    theta = least_squares(resid, theta, jac=jac, loss="cauchy", f_scale=fs, x_scale="jac").x
    z = r0 + j @ theta
    wts = 1.0 / (1.0 + (z / fs) ** 2)  # the Cauchy loss's weight per residual
    unit = max(1.0, float(np.sum(wts * z * z) / max(len(z) - model.n, 1)))
    # the robust weights' normal equations with the online rule (only directions the windows observe move): the
    # estimate from all windows, moving the directions whose information, divided by the variance of unit weight and
    # by how many windows share each one's noise (their residuals' correlation), is at least the prior's; the
    # covariance from their information divided by the variance of unit weight and by the windows covering each
    # stretch of rotation (the most that can share a reading or a gyro path: it also covers a systematic error the
    # residuals do not show, as a latency error the hard iron absorbs)
    jw = j * wts[:, None]
    lam_d, eta_d = jw.T @ j, -(jw.T @ r0)
    theta = posterior(lam0, theta0, lam_d, eta_d, overstated=unit * shared_noise(z * np.sqrt(wts), overlap))[0]
    k = unit * overlap
    cov = model.with_floor(posterior(lam0, theta0, lam_d / k, eta_d / k)[1])
    outliers = left_out + int(np.count_nonzero((wts.reshape(-1, 3) < 0.5).any(axis=1)))
    return model, theta, cov, z, outliers


def fit_recording(gyr: ArrayLike, dt: ArrayLike, mag_t: ArrayLike, prior: MagCalPrior | None = None,
                  soft_iron_model: SoftIronModel = "full", delay_s: float = 0.0,
                  acc: ArrayLike | None = None) -> OfflineFit:
    """Fit hard and soft iron over a whole recording (arrays as :func:`windows_of`). ``acc`` (N, 3), when given,
    sets the tilt for the state's heading bound (its last sample); without it the bound ignores the dip."""
    ws, overlap = windows_of(gyr, dt, mag_t, delay_s)
    online = OnlineMagCalibrator(prior, soft_iron_model)
    g = np.asarray(gyr, dtype=float).reshape(-1, 3)
    d = np.asarray(dt, dtype=float).reshape(-1)
    m_all = np.asarray(mag_t, dtype=float).reshape(-1, 3)
    ok = plausible(m_all)
    for inc, step, m_i, good in zip(quat.from_rotvec(g * d[:, None]).tolist(), d.tolist(), m_all.tolist(),
                                    ok.tolist(), strict=True):
        online.update(tuple(inc), step, tuple(m_i) if good else None, delay_s)
    model, theta, cov, z, outliers = fit_windows(ws, overlap, prior, soft_iron_model,
                                                 start=(online.theta, online.covariance))
    a, h = model.split(theta)
    m = np.asarray(mag_t, dtype=float).reshape(-1, 3)
    m = m[plausible(m)] / UT
    u = (m - h) @ a.T
    norms = np.linalg.norm(u, axis=1)
    scale = np.r_[np.ones(9), np.full(3, UT)]
    out_cov = model.output_covariance(theta, cov) * np.outer(scale, scale)
    bound = math.pi
    if len(u):
        if acc is not None:
            q = quat.from_accelerometer(np.asarray(acc, dtype=float).reshape(-1, 3)[-1])
            bound = heading_sd_bound(model, theta, cov, (q[0], q[1], q[2], q[3]), u[-1], STATE_HEADINGS)
        else:
            su = model.field_covariance(m[-1], cov)
            bound = math.sqrt(float(np.linalg.eigvalsh(su)[-1])) / float(norms[-1])
    state = CALIBRATED if bound <= CALIBRATED_SD_RAD else (CONVERGING if len(ws) else UNCALIBRATED)
    cal = MagCalibration(hard_iron_t=tuple(float(v) * UT for v in h),  # type: ignore[arg-type]
                         soft_iron=tuple(float(v) for v in a.reshape(9)),
                         covariance=tuple(float(v) for v in out_cov.reshape(144)), state=state, windows=len(ws),
                         converged_after_s=None, soft_iron_model=soft_iron_model)
    rms = 0.0
    if len(ws):
        jr, r0 = model.rows(ws)
        rms = float(np.sqrt(np.mean(np.square(r0 + jr @ theta))))
    return OfflineFit(calibration=cal, residual_rms_ut=rms, field_norm_ut=float(np.median(norms)) if len(u) else 0.0,
                      field_norm_sd_ut=float(np.std(norms)) if len(u) else 0.0, windows=len(ws), outliers=outliers,
                      unit_weight=float(np.mean(z * z)) if len(z) else 1.0)
