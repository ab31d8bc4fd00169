"""Validation by physics (:mod:`riann_ros.magcal.validate`): the calibrations a magnetometer can have pass (a
calibrated sensor, the online calibration's own estimates, a soft iron with the magnetometer's misalignment of a few
degrees), and each of the issue's bad ones is refused with its reason, numbers of any size included, without an
exception."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riann_ros.datasets.synthetic import generate
from riann_ros.magcal import validate
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import IDENTITY_9, UT
from riann_ros.magcal.synthetic import distort
from riann_ros.magcal.validate import (
    covariance_refusals,
    field_norm_refusals,
    hard_iron_refusals,
    refusals,
    soft_iron_refusals,
    typical_field_norm_t,
)

SOFT = np.array([[1.08, 0.04, 0.0], [0.04, 0.93, 0.02], [0.0, 0.02, 1.0]])  # symmetric, scales 0.9-1.1
COV = np.diag(np.r_[np.full(9, 1e-4), np.full(3, (0.5 * UT) ** 2)])


def rot(axis: str, deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    r = np.eye(3)
    r[i, i] = r[j, j] = c
    r[i, j], r[j, i] = -s, s
    return r


def test_calibrations_a_sensor_can_have_pass():
    assert refusals((20e-6, 0.0, -10e-6), IDENTITY_9, COV.reshape(144), 48e-6) == []
    assert refusals((0.0, 0.0, 0.0), SOFT.reshape(9), COV.reshape(144)) == []
    # the full model: the symmetric part times the magnetometer's misalignment (a few degrees) about any axis
    for axis in "xyz":
        assert soft_iron_refusals((rot(axis, 8.0) @ SOFT).reshape(9)) == []
    assert hard_iron_refusals((900e-6, 0.0, 0.0)) == []  # a large hard iron within the read range
    assert covariance_refusals(np.zeros(144)) == []  # known exactly (a floor is the calibration's business)
    # the online calibration's estimates: from the prior alone, and after a minute of rotation with a soft iron
    assert refusals(*_as_args(OnlineMagCalibrator().calibration())) == []
    rec = generate(duration=60, rate=100, motion="rotation", bias=0.0, gyr_noise=0.002, seed=4)
    raw = distort(rec.quat_ref, np.array([25.0, -12.0, 8.0]) * UT, np.linalg.inv(SOFT), noise_t=0.3e-6, seed=4)
    cal = OnlineMagCalibrator()
    from riann_ros import quaternion as quat

    inc = quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()
    for i in range(len(rec)):
        cal.update(tuple(inc[i]), float(rec.dt[i]), tuple(raw[i]), 0.0, tuple(rec.quat_ref[i]))  # type: ignore[arg-type]
    est = cal.calibration()
    assert est.windows > 20
    norm = typical_field_norm_t(est.hard_iron_t, est.soft_iron, raw)
    assert norm is not None and 40e-6 < norm < 50e-6  # the synthetic field's 44.7 µT
    assert validate.calibration_refusals(est, norm) == []


def _upper(i: int, j: int, v: float) -> np.ndarray:
    out = np.zeros((12, 12))
    out[i, j] = v
    return out


def _as_args(cal):
    return cal.hard_iron_t, cal.soft_iron, cal.covariance


@pytest.mark.parametrize(("soft", "reason"), [
    (np.diag([-1.0, -1.0, 1.0]), "holds a rotation of 180.0°"),  # the issue's: det +1
    (rot("z", 90.0), "holds a rotation of 90.0°"),
    (rot("x", 12.0) @ SOFT, "holds a rotation of 12.0°"),
    (np.diag([-1.0, 1.0, 1.0]), "is a reflection (det S = -1 < 0)"),
    (np.diag([1.0, 1.0, 0.0]), "is singular"),
    (1500.0 * np.eye(3), "scales the field by 1500–1500 along its principal axes, outside 0.2–5"),
    (np.diag([1.0, 1.0, 0.1]), "scales the field by 0.1–1"),
    (np.diag([1.0, 6.0, 1.0]), "scales the field by 1–6"),
])
def test_a_soft_iron_that_is_not_symmetric_positive_definite_or_out_of_scale_is_refused(soft, reason):
    got = soft_iron_refusals(soft.reshape(9))
    assert len(got) >= 1 and any(reason in r for r in got), got
    assert refusals((0.0, 0.0, 0.0), soft.reshape(9)) == got


def test_hard_iron_within_the_read_range():
    (why,) = hard_iron_refusals((999e-6, 0.0, 0.0))  # the file
    assert why.startswith("mag_hard_iron |h| = 999 µT is over 933 µT")
    assert hard_iron_refusals((0.0, 0.0, 0.2)) != []  # a field in gauss read as tesla
    assert hard_iron_refusals((math.nan, 0.0, 0.0)) == ["mag_hard_iron must hold finite numbers"]
    assert hard_iron_refusals((1.0, 2.0)) == ["mag_hard_iron must be 3 numbers, got 2"]


@pytest.mark.parametrize(("change", "reason"), [
    (lambda c: np.full_like(c, 1e308), "over its bound"),  # the issue's: today "Eigenvalues did not converge"
    (lambda c: c + np.diag(np.r_[np.zeros(9), np.full(3, (2e-3) ** 2)]), "over its bound"),  # σ 2 mT
    (lambda c: c + np.diag(np.r_[np.full(9, 30.0), np.zeros(3)]), "over its bound"),  # σ 5.5 per entry
    (lambda c: np.where(np.eye(12, k=1, dtype=bool), 1e308, c), "not positive semi-definite"),
    (lambda c: c + _upper(0, 1, 0.5e-4), "not symmetric"),
    (lambda c: c + 0.9e-4 * (np.eye(12, k=1) + np.eye(12, k=-1) + np.eye(12, k=2) + np.eye(12, k=-2))
     * (np.arange(12) < 9)[:, None] * (np.arange(12) < 9)[None, :], "not positive semi-definite"),
    (lambda c: -c, "negative variance"),
    (lambda c: np.where(np.eye(12, dtype=bool), c, np.inf), "finite"),
])
def test_a_covariance_that_is_no_covariance_is_refused_without_an_exception(change, reason):
    got = covariance_refusals(change(COV.copy()).reshape(144))
    assert len(got) == 1 and reason in got[0], got


def test_the_calibrated_field_is_an_earth_field():
    assert field_norm_refusals(45e-6) == [] and field_norm_refusals(16e-6) == [] and field_norm_refusals(95e-6) == []
    (why,) = field_norm_refusals(978e-6)  # the issue's: the 999 µT file's own output
    assert why.startswith("the calibrated field |m| = 978 µT (the median reading) is outside 15–100 µT")
    assert field_norm_refusals(8e-6) != []
    raw = np.array([[30e-6, 0.0, 40e-6], [np.nan, 0.0, 0.0], [0.0, 50e-6, 0.0], [0.0, 0.0, 60e-6]])
    assert typical_field_norm_t((0.0, 0.0, 0.0), IDENTITY_9, raw) == pytest.approx(50e-6)
    assert typical_field_norm_t((0.0, 0.0, 0.0), (2.0 * np.eye(3)).reshape(9), raw) == pytest.approx(100e-6)
    assert typical_field_norm_t((0.0, 0.0, 0.0), IDENTITY_9, np.full((2, 3), np.nan)) is None
    assert refusals((999e-6, 0.0, 0.0), IDENTITY_9, None, 978e-6)[1] == field_norm_refusals(978e-6)[0]
