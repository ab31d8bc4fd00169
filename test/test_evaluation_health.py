"""The stream's own health (riann_ros.evaluation.health): rate, jitter, holes, what the nodes' input gate does with
the stream, the unit checks and the rests with their mean gyro, read from the recording as it is."""

from __future__ import annotations

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros.constants import GRAVITY
from riann_ros.evaluation.health import StreamHealth
from riann_ros.gate import WARNING_TEXT
from riann_ros.recording import Recording

T0 = 1_700_000_000_000_000_000


def _health(rec: Recording, chunk: int) -> dict:
    h = StreamHealth(100.0, int(rec.stamps_ns[0]), len(rec))
    for k in range(0, len(rec), chunk):
        h.add(rec.slice(k, k + chunk))
    return h.result()


def test_holes_jitter_gate_verdicts_and_rests():
    rec = synthetic(rate=100.0, rest_s=4.0, move_s=20.0, gyr_bias=(0.01, -0.02, 0.005), t0_ns=T0)
    keep = np.ones(len(rec), bool)
    keep[1000:1020] = False  # a hole of 20 lost samples (0.21 s step)
    keep[1500:1580] = False  # a gap of 0.81 s > max_dt: the estimators restart
    rng = np.random.default_rng(0)
    stamps = rec.stamps_ns + rng.integers(-1_000_000, 1_000_001, len(rec))  # ±1 ms jitter
    stamps[0] = rec.stamps_ns[0]
    acc = rec.acc.copy()
    acc[2000] = np.nan  # a sample the gate rejects
    rec = Recording(stamps[keep], acc[keep], rec.gyr[keep], rec.quat_ref[keep], rec.score_mask[keep], name="h")
    results = [_health(rec, chunk) for chunk in (len(rec), 333)]
    h = results[0]
    assert results[1] == {k: pytest.approx(v) if isinstance(v, float) else v for k, v in h.items()}  # any chunking
    assert h["samples"] == len(rec) and h["rate_hz"] == 100.0
    assert h["holes"] == 2 and h["samples_missing"] == 100
    assert h["longest_hole_s"] == pytest.approx(0.81, abs=0.003)
    assert 0.3 < h["step_std_ms"] < 60.0 and 8.0 <= h["step_min_ms"] and h["step_max_ms"] > 800.0
    assert h["rejected"] == {"non_finite": 1} and h["restarts"] == {"gap": 1}
    assert h["warnings"] == [] and h["unit_findings"] == []
    (rest,) = h["rests"]  # the 4 s before the motion; its mean gyro is the bias
    assert rest["start_s"] == pytest.approx(0.0, abs=0.05) and 2.5 < rest["end_s"] < 4.1
    assert rest["gyr_mean_dps"] == pytest.approx(np.degrees([0.01, -0.02, 0.005]).tolist(), abs=0.01)


def test_an_accelerometer_in_g_is_warned_as_the_node_warns_it():
    rec = synthetic(rate=100.0, move_s=6.0, t0_ns=T0)
    rec.acc = rec.acc / GRAVITY
    h = _health(rec, 250)
    assert h["warnings"] == [WARNING_TEXT["acc_in_g"]]
    assert any("looks like g read as m/s2" in f for f in h["unit_findings"]), h["unit_findings"]
    assert h["rests"] == []  # no gravity-sized specific force: nothing counts as a rest
