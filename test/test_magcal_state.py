"""State as records (issue: the magnetometer as one wing): the online calibrator's, the front end's and RIANN's
magnetic heading's state are one value each, so a snapshot restored replays the same numbers, and a reset is the
record anew."""

from __future__ import annotations

import numpy as np
from helpers_mag import moving

from riann_ros import quaternion as quat
from riann_ros.estimators.riann.s7a_mag import HeadingState, MagHeading
from riann_ros.magcal.frontend import FrontEndConfig, LatencySettings, MagFrontEnd
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import UT
from riann_ros.magcal.synthetic import distort


def _inputs(n: int = 3000):
    rec = moving(duration=n / 100.0, seed=4)
    raw = distort(rec.quat_ref, np.array([15.0, -10.0, 5.0]) * UT, noise_t=0.3e-6, seed=1)
    inc = [tuple(v) for v in quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()]
    rv = [tuple(v) for v in (rec.gyr * rec.dt[:, None]).tolist()]
    qs = [tuple(v) for v in rec.quat_ref.tolist()]
    return inc, rv, rec.dt.tolist(), [tuple(v) for v in raw.tolist()], qs, rec


def test_a_restored_calibrator_replays_the_same_numbers():
    inc, _, dts, mags, qs, _ = _inputs()
    cal = OnlineMagCalibrator()
    for i in range(1500):
        cal.update(inc[i], dts[i], mags[i], 0.01, qs[i])
    snap = cal.snapshot()
    first = [cal.update(inc[i], dts[i], mags[i], 0.01, qs[i]) for i in range(1500, 3000)]
    assert cal.windows > snap.windows  # the run changed the state, not the snapshot
    cal.restore(snap)
    again = [cal.update(inc[i], dts[i], mags[i], 0.01, qs[i]) for i in range(1500, 3000)]
    assert again == first and cal.windows > 0


def test_a_restored_front_end_replays_the_same_numbers():
    inc, rv, dts, mags, qs, rec = _inputs()
    front = MagFrontEnd(latency=LatencySettings(0.0, estimate=True, compensate=True))

    def run(a: int, b: int) -> list:
        return [front.step(inc[i], rv[i], dts[i], mags[i], qs[i], True) for i in range(a, b)]

    run(0, 1500)
    snap = front.snapshot()
    first = run(1500, 3000)
    front.restore(snap)
    assert run(1500, 3000) == first
    rows = MagFrontEnd()
    acc, gyr = rec.acc.tolist(), rec.gyr.tolist()
    rows.rows(acc[:1500], gyr[:1500], dts[:1500], mags[:1500])
    snap = rows.snapshot()
    one = rows.rows(acc[1500:], gyr[1500:], dts[1500:], mags[1500:])
    rows.restore(snap)
    two = rows.rows(acc[1500:], gyr[1500:], dts[1500:], mags[1500:])
    assert one.field == two.field and one.realign == two.realign


def test_the_heading_state_is_one_record():
    inc, _, dts, mags, qs, _ = _inputs(2000)
    front = MagFrontEnd(FrontEndConfig(calibrate=False, test=False))
    h = MagHeading(9.0, True, front)
    assert h.s == HeadingState()
    for i in range(1000):
        h.step(qs[i], inc[i], dts[i], mags[i])
    snap = h.snapshot()
    assert snap == h.s and snap is not h.s and snap.started
    first = [h.step(qs[i], inc[i], dts[i], mags[i]) for i in range(1000, 2000)]
    h.restore(snap)
    assert [h.step(qs[i], inc[i], dts[i], mags[i]) for i in range(1000, 2000)] == first
    h.reset()
    assert h.s == HeadingState()  # a reset is the record anew
