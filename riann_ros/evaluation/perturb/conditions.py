"""Conditions (perturbations joined with ``+``) and parsing ``kind:args`` (ROS-free); :data:`DEFINITIONS` says what
each kind does and is the one source of the ``--perturb`` help and of the parse errors."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from riann_ros.evaluation.perturb.base import NONE, Perturbation, Transform
from riann_ros.evaluation.perturb.dropout import Dropout
from riann_ros.evaluation.perturb.signal import Bias, GyroScale, Magnetic, MagneticLag
from riann_ros.evaluation.perturb.timing import Fifo, Jitter, Latency, Rate

DEFINITIONS = {
    "jitter": "jitter:10/20/30ms (set) or jitter:8-32ms (range): each next sample an interval later drawn uniformly; "
    "acc/gyr = means of the piecewise-linear signal over the interval; reference slerped at the sample",
    "rate": "rate:HZ: a regular stream at HZ made like jitter (interval means), causal, chunk by chunk",
    "points": "jitter:...:points, rate:HZ:points: the same stamps, each sample the signal at its stamp (linear "
    "between the recording's samples) instead of the interval mean",
    "lowpass": "rate:HZ:lowpass: the same stamps, each sample the signal at its stamp after a first-order low-pass "
    "of time constant half a step (a MEMS sensor's anti-alias filter, stamped at data-ready: a group delay of "
    "half a step, like interval means); reference at the stamp",
    "latency": "latency:LO-HIms: each stamp = the measurement time + a delay drawn uniformly from LO-HI (kept in "
    "order); samples and reference unchanged",
    "fifo": "fifo:Pms: the FIFO read every P ms from the first stamp; each message stamped at its read time, "
    "10 us apart in order; samples and reference unchanged",
    "bias": "bias:X,Y,Z (deg/s) or bias:random:SIGMA (deg/s per axis, drawn per sequence): added to the gyro "
    "from the first sample of the sequence",
    "gyro": "gyro:scale:F: the gyro's values multiplied by F from the first sample of the sequence (a unit slip: "
    "deg/s read as rad/s is 57.2958)",
    "dropout": "dropout:LO-HIs@Ts: holes of LO-HI s (uniform) about every T s (exponential spacing), starting at "
    "a scored sample; the samples in a hole are removed",
    "magnetic": "magnetic:offset:X,Y,Z (µT, sensor frame, from the first sample) or magnetic:disturb:B@T0-T1s "
    "(B µT fixed in the sensor frame, direction drawn per sequence, T0-T1 s after the first sample): added "
    "to the magnetometer; magnetic:soft:D11,D12,...,D33 (a soft iron: the reading multiplied by the row-major "
    "3x3 matrix D from the first sample; before an offset in the same condition: D m + offset); magnetic:lag:Dms "
    "(a late magnetometer: each reading carries the field of D earlier under its own stamp, linear between the "
    "recording's samples; no reading in the sequence's first D; IMU samples, stamps and reference unchanged); "
    "recordings without a magnetometer are left as they are",
    "seeding": "per sequence, condition and perturbation: sha256 of '<seed>:<sequence>:<condition>:<index>'",
}
# the accepted forms of every kind (``points`` is the suffix of jitter and rate), in the order of DEFINITIONS
EXAMPLES = {
    "jitter": ("jitter:10/20/30ms", "jitter:8-32ms"),
    "rate": ("rate:50",),
    "points": ("jitter:5-15ms:points", "rate:50:points"),
    "lowpass": ("rate:50:lowpass",),
    "latency": ("latency:0-20ms",),
    "fifo": ("fifo:20ms",),
    "bias": ("bias:3,3,0", "bias:random:2 (deg/s)"),
    "gyro": ("gyro:scale:57.2958",),
    "dropout": ("dropout:0.1-0.6s@10s",),
    "magnetic": ("magnetic:offset:20,0,-10 (µT)", "magnetic:disturb:40@10-20s",
                 "magnetic:soft:1.15,0.05,0,0,0.85,0.05,0.05,0,1", "magnetic:lag:300ms"),
}


def accepted_forms() -> str:
    """Every kind's forms, for the ``--perturb`` help and the parse errors."""
    return ", ".join(f for forms in EXAMPLES.values() for f in forms)


# ---------------------------------------------------------------------------------------------------
# conditions
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Condition:
    """Perturbations applied in order; the empty condition is ``none``."""

    parts: tuple[Perturbation, ...] = ()

    @property
    def label(self) -> str:
        return "+".join(p.text() for p in self.parts) or NONE

    def nominal_rate(self, rate_hz: float) -> float:
        for p in self.parts:
            rate_hz = p.nominal_rate(rate_hz)
        return rate_hz

    def start(self, rngs: list[np.random.Generator]) -> list[Transform]:
        return [p.start(rng) for p, rng in zip(self.parts, rngs, strict=True)]


_NUM = r"[0-9]*\.?[0-9]+(?:e[-+]?[0-9]+)?"


def _seconds(text: str, unit: str) -> float:
    return float(text) * (1e-3 if unit == "ms" else 1.0)


def _points(parse: Callable[[str], Perturbation | None]) -> Callable[[str], Perturbation | None]:
    """``parse`` that also takes a ``:points`` suffix (jitter and rate: the signal at the stamps)."""

    def wrapped(args: str) -> Perturbation | None:
        base, sep, tail = args.rpartition(":")
        if sep and tail == "points":
            p = parse(base)
            return replace(p, points=True) if isinstance(p, Jitter) else None
        return parse(args)

    return wrapped


def _lowpass(parse: Callable[[str], Perturbation | None]) -> Callable[[str], Perturbation | None]:
    """``parse`` (rate) that also takes a ``:lowpass`` suffix (a first-order low-pass sensor's samples)."""

    def wrapped(args: str) -> Perturbation | None:
        base, sep, tail = args.rpartition(":")
        if sep and tail == "lowpass":
            p = parse(base)
            return replace(p, lowpass=True) if isinstance(p, Rate) and not p.points else None
        return parse(args)

    return wrapped


def _jitter(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM}(?:/{_NUM})*)(ms|s)", args)
    if m:
        vals = tuple(_seconds(v, m.group(2)) for v in m.group(1).split("/"))
        return Jitter(choices=vals) if all(v > 0 for v in vals) else None
    m = re.fullmatch(rf"({_NUM})-({_NUM})(ms|s)", args)
    if m:
        lo, hi = _seconds(m.group(1), m.group(3)), _seconds(m.group(2), m.group(3))
        return Jitter(lo=lo, hi=hi) if 0 < lo <= hi else None
    return None


def _rate(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM})(?:hz)?", args)
    return Rate(hz=float(m.group(1))) if m and float(m.group(1)) > 0 else None


def _bias(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"random:({_NUM})", args)
    if m:
        return Bias(sigma=float(m.group(1)))
    m = re.fullmatch(rf"(-?{_NUM}),(-?{_NUM}),(-?{_NUM})", args)
    return Bias(dps=(float(m.group(1)), float(m.group(2)), float(m.group(3)))) if m else None


def _gyro(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"scale:(-?{_NUM})", args)
    factor = float(m.group(1)) if m else 0.0
    return GyroScale(factor) if factor != 0.0 and np.isfinite(factor) else None


def _latency(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM})-({_NUM})(ms|s)", args)
    if not m:
        return None
    lo, hi = _seconds(m.group(1), m.group(3)), _seconds(m.group(2), m.group(3))
    return Latency(lo, hi) if 0 <= lo <= hi else None


def _fifo(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM})(ms|s)", args)
    if not m:
        return None
    period = _seconds(m.group(1), m.group(2))
    return Fifo(period) if period > 0 else None


def _dropout(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM})-({_NUM})s@({_NUM})s", args)
    if not m:
        return None
    lo, hi, every = (float(v) for v in m.groups())
    return Dropout(lo, hi, every) if 0 < lo <= hi and every > 0 else None


def _magnetic(args: str) -> Perturbation | None:
    m = re.fullmatch(",".join([rf"soft:(-?{_NUM})", *[rf"(-?{_NUM})"] * 8]), args)
    if m:
        d = tuple(float(v) for v in m.groups())
        return Magnetic(soft=d) if abs(float(np.linalg.det(np.reshape(d, (3, 3))))) > 1e-6 else None
    m = re.fullmatch(rf"offset:(-?{_NUM}),(-?{_NUM}),(-?{_NUM})", args)
    if m:
        return Magnetic(offset=(float(m.group(1)), float(m.group(2)), float(m.group(3))))
    m = re.fullmatch(rf"lag:({_NUM})(ms|s)", args)
    if m:
        lag = _seconds(m.group(1), m.group(2))
        return MagneticLag(lag) if lag >= 1e-6 else None
    m = re.fullmatch(rf"disturb:({_NUM})(?:ut)?@({_NUM})-({_NUM})s", args)
    if not m:
        return None
    strength, t0, t1 = (float(v) for v in m.groups())
    return Magnetic(strength=strength, t0=t0, t1=t1) if t0 < t1 else None


_PARSERS = {"jitter": _points(_jitter), "rate": _lowpass(_points(_rate)), "latency": _latency, "fifo": _fifo,
            "bias": _bias, "gyro": _gyro, "dropout": _dropout, "magnetic": _magnetic}


def parse_perturbation(text: str) -> Perturbation:
    """One ``kind:args`` item (see the module docstring); ``ValueError`` with the accepted forms."""
    kind, _, args = text.strip().lower().replace(" ", "").partition(":")
    parser = _PARSERS.get(kind)
    p = parser(args) if parser else None
    if p is None:
        raise ValueError(f"bad perturbation {text!r}; accepted: {accepted_forms()}")
    return p


def parse_condition(text: str) -> Condition:
    """``none`` or perturbations joined with ``+`` (``jitter:10/20/30ms+bias:3,3,0``)."""
    t = text.strip()
    if not t or t.lower() == NONE:
        return Condition()
    return Condition(tuple(parse_perturbation(p) for p in t.split("+")))
