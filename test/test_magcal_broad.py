"""The calibration on real data: BROAD trials with an injected hard iron (``magnetic:offset:20,0,-10`` as the
evaluator injects it). The gyro is debiased by the bias front end, the latency is BROAD's magnetometer's (stage 7b
settles at 9–11 ms on every trial; 10 ms here), the reference attitude gives the tilt. Skips without BROAD."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riann_ros import quaternion as quat
from riann_ros.estimators.bias import GyroBiasFrontEnd
from riann_ros.magcal.offline import fit_recording
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import CALIBRATED, UT
from riann_ros.rotations import rotate

pytestmark = [pytest.mark.broad, pytest.mark.slow]
OFFSET_UT = np.array([20.0, 0.0, -10.0])
DELAY_S = 0.010


@pytest.mark.parametrize("number", ["02", "21"])  # slow rotation; fast rotation and translation
def test_injected_offset_is_found_online_and_offline(broad_trial, number):
    rec = broad_trial(number)
    gyr = rec.gyr - GyroBiasFrontEnd(float(rec.dt[0])).update_batch(rec.acc, rec.gyr, rec.dt)
    raw = rec.mag + OFFSET_UT * UT
    q = rec.quat_ref
    ok = np.isfinite(q).all(axis=1)
    q = q[np.maximum.accumulate(np.where(ok, np.arange(len(q)), 0))]
    inc = quat.from_rotvec(gyr * rec.dt[:, None]).tolist()
    cal = OnlineMagCalibrator()  # the default, full soft-iron model
    z = []
    for i, (d, dt, m, qi) in enumerate(zip(inc, rec.dt.tolist(), raw.tolist(), q.tolist(), strict=True)):
        u = cal.update(tuple(d), dt, tuple(m), DELAY_S, tuple(qi))  # type: ignore[arg-type]
        if cal.windows and i % 20 == 0 and ok[i] and u is not None:
            mw = rotate(tuple(qi), u)  # type: ignore[arg-type]
            mr = quat.rotate(np.asarray(qi), rec.mag[i])
            err = math.remainder(math.atan2(mw[0], mw[1]) - math.atan2(mr[0], mr[1]), 2 * math.pi)
            z.append(err / cal.heading_sd_rad(tuple(qi), mw))  # type: ignore[arg-type]
    c = cal.calibration()
    assert cal.state == CALIBRATED and cal.converged_after_s is not None
    assert np.linalg.norm(np.array(c.hard_iron_t) / UT - OFFSET_UT) < 1.5
    # the calibration-induced heading error (against the recorded field's) is inside 2σ most of the time
    assert np.mean(np.abs(np.array(z)) <= 2.0) > 0.85
    off = fit_recording(gyr, rec.dt, raw, delay_s=DELAY_S, acc=rec.acc)
    assert np.linalg.norm(np.array(off.calibration.hard_iron_t) / UT - OFFSET_UT) < 1.5  # the acceptance
    assert off.residual_rms_ut < 3.0
