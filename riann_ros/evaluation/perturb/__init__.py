"""Perturbations: make a recording behave like a real sensor stream, chunk by chunk (ROS-free).

``riann-bag-eval --perturb CONDITION`` (repeatable: each condition is evaluated like another rate). A
condition is ``none`` or perturbations joined with ``+``, applied in that order to each scenario
sequence, after the scenario and before the estimators:

``jitter:10/20/30ms`` / ``jitter:8-32ms``
    Irregular stamps: the next sample comes an interval later drawn uniformly from the set (or the
    range); its acc and gyr are the means of the recording's signal over that interval (the signal
    taken as piecewise linear between samples, so a short interval interpolates and a long one
    averages); the reference is slerped at the new stamp, the score mask taken from the nearest sample.
``rate:50``
    A regular stream at 50 Hz made the same way (``jitter`` with one interval): causal resampling,
    chunk by chunk. (``--rates`` resamples the whole recording with the FFT, as in the paper.)
``jitter:5-15ms:points`` / ``rate:50:points``
    The same stamps, but each sample is the signal *at* its stamp (interpolated linearly between the
    recording's samples) instead of its mean over the interval: a sensor read at irregular times, which
    is what a ROS stamp means (the measurement time).
``rate:50:lowpass``
    The same stamps, each sample the signal at its stamp after a first-order low-pass of time constant
    half a step (10 ms at 50 Hz), computed exactly for the piecewise-linear signal: a MEMS sensor whose
    anti-alias filter has a group delay of half a step, stamped at data-ready. The reference is taken at
    the stamp, so the samples lag it by about half a step, as interval means do.
``latency:0-20ms``
    Receive-time stamps: each sample keeps its values and its reference, but its stamp is the
    measurement time plus a delivery delay drawn uniformly from the range (stamps kept in order, at
    least 1 µs apart) — what a driver that stamps on arrival over USB, Bluetooth or a busy host
    gives. The samples underneath stay regular; only the stamps jitter.
``fifo:20ms``
    FIFO read-out: the host reads the sensor's FIFO every 20 ms (from the sequence's first stamp) and
    stamps each message on arrival, at the read time, 10 µs apart in order — a driver that polls a
    FIFO. Samples and reference unchanged; the stamps come in bursts.
``bias:3,3,0`` / ``bias:random:2``
    A constant gyroscope bias (°/s per axis) from the first sample of the sequence, or one drawn per
    sequence from N(0, (2 °/s)²) per axis.
``gyro:scale:57.2958`` / ``gyro:scale:0.001``
    The gyroscope's values multiplied by the factor from the first sample of the sequence: a unit slip (a
    driver that gives deg/s where rad/s is meant: 57.2958; mdeg/s read as deg/s: 0.001).
``dropout:0.1-0.6s@10s``
    Lost messages: holes of a length drawn uniformly from the range, about every 10 s (exponential
    spacing), starting only where the sensor moves (a scored sample); the samples in a hole are removed.
``magnetic:offset:20,0,-10`` / ``magnetic:disturb:40@10-20s``
    The magnetometer (recordings without one are left as they are): a constant hard-iron offset (µT
    per sensor axis) from the first sample, or a field of 40 µT fixed in the sensor frame (a magnet or
    a steel part carried with the sensor), in a direction drawn per sequence, from 10 s to 20 s after
    the sequence's first sample. ``magnetic:soft:D11,D12,...,D33``: a soft iron, each reading multiplied by the
    row-major 3×3 matrix from the first sample.
``magnetic:lag:300ms`` / ``magnetic:lag:0.1s``
    A late magnetometer (a slow driver): each field reading carries the field of 300 ms earlier under its own
    stamp. The field at stamp t is the recording's field at t − 0.3 s, linear between the two recording samples
    around that time (the earlier one where the later has no field); in the sequence's first 0.3 s there is no
    earlier field, so no reading (those samples run 6D, as before a driver's first message; the same after a
    clock that went back). Causal, chunk by chunk; the IMU samples, their stamps and the reference are unchanged.

Every random draw is seeded per sequence, condition and perturbation (``--seed``), so every estimator
sees the same perturbed stream and a bag gives the same stream whatever its chunking.
"""

from riann_ros.evaluation.perturb.base import NONE, Perturbation, Transform, concat
from riann_ros.evaluation.perturb.conditions import (
    DEFINITIONS,
    EXAMPLES,
    Condition,
    accepted_forms,
    parse_condition,
    parse_perturbation,
)
from riann_ros.evaluation.perturb.dropout import Dropout
from riann_ros.evaluation.perturb.signal import Bias, GyroScale, Magnetic, MagneticLag
from riann_ros.evaluation.perturb.timing import Fifo, Jitter, Latency, Rate

__all__ = [
    "DEFINITIONS",
    "EXAMPLES",
    "NONE",
    "Bias",
    "Condition",
    "Dropout",
    "Fifo",
    "GyroScale",
    "Jitter",
    "Latency",
    "Magnetic",
    "MagneticLag",
    "Perturbation",
    "Rate",
    "Transform",
    "accepted_forms",
    "concat",
    "parse_condition",
    "parse_perturbation",
]
