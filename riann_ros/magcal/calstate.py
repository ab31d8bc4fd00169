"""The online calibrator's state as one record (ROS-free): :class:`CalibratorState` holds everything
:class:`~.online.OnlineMagCalibrator` changes after its construction, so a snapshot, a restore or a comparison of two
states is one value (:meth:`~.online.OnlineMagCalibrator.snapshot`). What its construction fixes (the model, the
prior as information) is not state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

from riann_ros.magcal.changes import Changes
from riann_ros.magcal.hypothesis import PriorTest
from riann_ros.magcal.model import Array, CalModel
from riann_ros.magcal.records import UNCALIBRATED, CalState
from riann_ros.magcal.solver import InfoEstimate
from riann_ros.magcal.windows import Windower
from riann_ros.rotations import Quat, Vec


@dataclass
class Applied:
    """The calibration the readings get (``a`` row-major soft iron, ``c`` hard iron times soft iron, µT, plain
    floats for the per-sample product) and the estimate's own (the same once the prior is rejected)."""

    a: tuple[float, ...]
    c: tuple[float, ...]
    est_a: tuple[float, ...]
    est_c: tuple[float, ...]


@dataclass
class SdCache:
    """The cached field covariances of the heading σ (µT²: xx, xy, xz, yy, yz, zz): ``su`` of the estimate (``H₁``),
    ``su0`` of a saved prior (``H₀``: its covariance; zeros for a configured one); the windower's attitude they were
    computed at (None: stale), and the calibrated field's σ in its worst direction (µT) computed with ``su``."""

    q_refresh: Quat | None = None
    su: tuple[float, ...] = (0.0,) * 6
    su0: tuple[float, ...] = (0.0,) * 6
    field_sd_ut: float = math.inf


@dataclass
class CalibratorState:
    """Everything the online calibrator changes (module docstring)."""

    est: InfoEstimate  # the estimate in use (information form)
    test: PriorTest  # does the prior still hold?
    windower: Windower  # the open window
    windows: int  # windows in the information (a saved calibration's included)
    applied: Applied
    changes: Changes  # what a filter's heading built on the field must follow
    cand: InfoEstimate | None = None  # learns from consecutive rejected windows
    agree: int = 0  # consecutive windows that agree with a rejected prior
    switches: int = 0  # times a candidate replaced the estimate
    rejected: int = 0  # windows rejected as disturbed in this run
    converged_after_s: float | None = None  # s after this run's first sample
    q: Quat | None = None  # the attitude last passed (the state's tilt)
    m_last: Vec | None = None  # the last raw reading (µT)
    sd: SdCache = field(default_factory=SdCache)
    bound: float = math.pi  # the last state bound (rad)
    state: CalState = UNCALIBRATED


class Calibrator(Protocol):
    """What the calibrator's parts (:mod:`.decisions`, :mod:`.knowledge`) read of it: its state, what its
    construction fixed, and the calibration in use."""

    s: CalibratorState
    model: CalModel
    lam0: Array  # the prior's information
    theta0: Array  # the prior
    fixed: bool  # the readings always get the prior (the test as a monitor)

    @property
    def trusted(self) -> bool: ...

    @property
    def covariance(self) -> Array: ...

    @property
    def h1_covariance(self) -> Array: ...

    @property
    def in_use(self) -> Array: ...
