"""riann_ros/estimators/consensus.py, consensus_rows.py and vqf_sigma.py: the minimum-variance weight, the disagreement
test, a block equals its samples, RIANN's inclination through a hole's hand-over, VQF's σ from its state; the
consensus at most the better of RIANN and VQF on the bundled bags and on BROAD trials."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import ROOT, rmse
from riann_ros import quaternion as quat
from riann_ros.datasets.synthetic import generate
from riann_ros.estimators import create
from riann_ros.estimators.consensus import ConsensusEstimator, _weigh
from riann_ros.estimators.riann.s4a_ensemble import gravity_rows
from riann_ros.estimators.vqf_sigma import VqfSigma, VqfTerms
from riann_ros.stream import EstimatorStream, GateConfig

DEG = math.pi / 180.0


def _holed(seconds: float = 12.0, rate: float = 200.0):
    """A synthetic recording and its steps with two holes (0.3 s, beyond restart_gap) in motion."""
    rec = generate(duration=seconds, rate=rate, seed=3, bias=0.03)
    dt = np.full(len(rec.acc), 1.0 / rate)
    for t in (5.0, 8.5):
        dt[int(t * rate)] = 0.3
    return rec, dt


# -- the combination ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("var_r", "var_v", "rho"), [(1.0, 1.0, 0.0), (1.0, 4.0, 0.0), (4.0, 1.0, 0.3),
                                                     (1.0, 2.0, -0.4), (2.0, 3.0, 0.6)])
def test_weight_minimises_the_combined_variance(var_r, var_v, rho):
    cov = rho * math.sqrt(var_r * var_v)
    w, var = _weigh(var_r, var_v, cov, var_r + var_v - 2 * cov)
    grid = np.linspace(0.0, 1.0, 100001)
    v = grid**2 * var_r + (1 - grid) ** 2 * var_v + 2 * grid * (1 - grid) * cov
    assert w == pytest.approx(grid[np.argmin(v)], abs=1e-4)
    assert var == pytest.approx(v.min(), rel=1e-6)
    if rho == 0.0:
        assert w == pytest.approx(var_v / (var_r + var_v))


def test_weight_is_kept_in_the_unit_interval_where_a_correlation_would_extrapolate():
    # ρ = 0.9 with σ_V = 2σ_R: the unconstrained optimum puts more than all weight on RIANN; kept at 1, σ RIANN's
    var_r, var_v = 1.0, 4.0
    cov = 0.9 * 2.0
    assert (var_v - cov) / (var_r + var_v - 2 * cov) > 1.0
    assert _weigh(var_r, var_v, cov, var_r + var_v - 2 * cov) == (1.0, var_r)


def _tilted(q: tuple[float, float, float, float], deg: float) -> tuple[float, float, float, float]:
    """``q`` turned by ``deg`` about the sensor's x axis."""
    w, x, y, z = quat.multiply(np.asarray(q), quat.from_rotvec([deg * DEG, 0.0, 0.0])).tolist()
    return w, x, y, z


def test_disagreement_beyond_the_sigmas_follows_the_healthy_one_and_widens_sigma():
    est = ConsensusEstimator()
    level = (1.0, 0.0, 0.0, 0.0)
    f_steady = [0.0, 0.2, 0.0, 0.001]  # spread, rate, hand-over σ, bias σ (rad/s): settled
    s_r = 0.4 * DEG
    steady = VqfTerms(1e-6, 1e-7, 3e-5, 1e-6, 0.0)
    # 10° apart where each says ~0.3–0.4°: not explained
    q, s = est._one(list(level), _tilted(level, 10.0), s_r, f_steady, steady)
    g = gravity_rows(np.asarray([q]))[0]
    between = math.degrees(math.acos(g[2]))
    assert 2.0 < between < 8.0  # both healthy: the weight stays, between the two
    assert (5.0 * DEG / s) ** 2 < 5.991  # σ widened: either opinion may be the truth (5° from the output)
    # VQF just after a hole (its transient outweighs its steady terms): RIANN's inclination
    sick = steady._replace(transient=(1.0 * DEG) ** 2)
    assert sick.unhealthy and not steady.unhealthy
    q2, _ = est._one(list(level), _tilted(level, 10.0), s_r, f_steady, sick)
    assert math.degrees(math.acos(gravity_rows(np.asarray([q2]))[0][2])) < 0.5
    # within their σ the test does not act: the plain minimum-variance weight
    _, s3 = est._one(list(level), _tilted(level, 0.2), s_r, f_steady, steady)
    assert s3 < min(s_r, math.sqrt(steady.total))


# -- the estimator --------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_a_block_equals_its_samples_through_holes():
    rec, dt = _holed()
    est = create("consensus")
    qb = est.update_batch(rec.acc, rec.gyr, dt)
    sb = est.sigma(np.zeros(len(qb), dtype=bool))
    est.reset()
    qs, ss = [], []
    for a, g, d in zip(rec.acc, rec.gyr, dt, strict=True):
        qs.append(est.update(a, g, d))
        ss.append(est.sigma(np.zeros(1, dtype=bool))[0])
    assert np.abs(np.array(qs) - qb).max() < 1e-5
    np.testing.assert_allclose(np.array(ss), sb, rtol=1e-4, atol=1e-9)
    assert np.isfinite(sb).all() and (sb > 0).all()
    # a batch continues from the state left by an earlier one
    est.reset()
    n = len(dt) // 3
    q12 = np.vstack([est.update_batch(rec.acc[:n], rec.gyr[:n], dt[:n]),
                     est.update_batch(rec.acc[n:], rec.gyr[n:], dt[n:])])
    assert np.abs(q12 - qb).max() < 1e-5


@pytest.mark.slow
def test_riann_through_a_holes_hand_over_and_both_opinions_elsewhere():
    rec, dt = _holed()
    est = ConsensusEstimator()
    q = est.update_batch(rec.acc, rec.gyr, dt)
    hand = est.riann.last.features[:, 2] > 0.0
    assert hand.sum() > 50  # the two holes' hand-overs
    np.testing.assert_allclose(q[hand], est.last.riann[hand], atol=1e-12)
    np.testing.assert_allclose(est.sigma(np.zeros(len(q), dtype=bool))[hand], est.riann.last.sigma_rad[hand])
    # elsewhere the output lies between the two opinions (on the great circle through them)
    g, gr, gv = gravity_rows(q[~hand]), gravity_rows(est.last.riann[~hand]), gravity_rows(est.last.vqf[~hand])
    ang = lambda a, b: np.arccos(np.clip(np.sum(a * b, axis=1), -1, 1))  # noqa: E731
    assert np.allclose(ang(gr, g) + ang(g, gv), ang(gr, gv), atol=1e-6)
    assert (ang(gr, g) > 1e-4).mean() > 0.5  # not RIANN's alone
    # the heading and its σ are RIANN's
    np.testing.assert_allclose(est.sigma(np.zeros(len(q), dtype=bool))[:, 1], est.riann.last.sigma_rad[:, 1])
    assert quat.heading_error(q, est.last.riann).max() < 1e-6


@pytest.mark.slow
def test_vqf_on_riann_rows_learns_a_turn_on_bias_vqf_alone_does_not():
    rec = generate(duration=40.0, seed=1, bias=(0.06, -0.05, 0.0))  # ~4.5 °/s, above VQF's 2 °/s bias clip
    dt = np.full(len(rec.acc), 0.005)
    cons = ConsensusEstimator()
    cons.update_batch(rec.acc, rec.gyr, dt)
    m = np.asarray(rec.score_mask, dtype=bool)
    e_rows = np.degrees(quat.inclination_error(rec.quat_ref, cons.last.vqf))[m]
    e_vqf = np.degrees(quat.inclination_error(rec.quat_ref, create("vqf").update_batch(rec.acc, rec.gyr, dt)))[m]
    assert np.sqrt(np.mean(e_rows**2)) < 0.5 * np.sqrt(np.mean(e_vqf**2))


def test_parameters_are_riann_s_and_tau_acc_and_change_at_run_time():
    est = create("consensus", ensemble=1, tau_acc=1.5)
    assert est.riann.params["ensemble"] == 1 and est.vqf.tau_acc == 1.5
    est.set_params(tau_acc=2.0, hole_blend=False)
    assert est.vqf.tau_acc == 2.0 and est.vqf_sigma.tau_acc == 2.0 and est.riann.params["hole_blend"] is False
    with pytest.raises(ValueError, match="unknown parameter"):
        create("consensus", beta=0.1)
    est.update_batch(np.tile([0.0, 0.0, 9.81], (50, 1)), np.zeros((50, 3)), np.full(50, 0.005))
    d = est.diagnostics()
    assert float(d["consensus weight on RIANN"]) >= 0.0 and "RIANN-VQF disagreement (deg)" in d


# -- VQF's σ from its state -----------------------------------------------------------------------------------------
def test_vqf_sigma_state_leaves_the_attitude_and_follows_the_bias_estimate():
    rec = generate(duration=20.0, seed=2, bias=0.02)
    dt = np.full(len(rec.acc), 0.005)
    plain, state = create("vqf"), create("vqf", sigma_model="state")
    q0, q1 = plain.update_batch(rec.acc, rec.gyr, dt), state.update_batch(rec.acc, rec.gyr, dt)
    assert np.array_equal(q0, q1)
    no_field = np.zeros(len(q0), dtype=bool)
    assert (plain.sigma(no_field)[:, 0] == 2.0 * DEG).all()  # vqf's own numbers unchanged by default
    s = state.sigma(no_field)[:, 0]
    assert s[0] > 1.0 * DEG and s[-1] < 0.5 * DEG  # from a fresh start's σ to a settled bias's
    np.testing.assert_array_equal(state.sigma(no_field)[:, 1], plain.sigma(no_field)[:, 1])
    per = create("vqf", sigma_model="state")
    ss = []
    for a, g, d in zip(rec.acc[:400], rec.gyr[:400], dt[:400], strict=True):
        per.update(a, g, d)
        ss.append(per.sigma(np.zeros(1, dtype=bool))[0, 0])
    np.testing.assert_allclose(ss, s[:400], rtol=1e-9)


def test_vqf_sigma_transient_decays_with_tau_acc():
    m = VqfSigma(tau_acc=3.0)
    m.step(0.01, 0.0, 9.80665, 0.0)
    m.kick(0.1)
    t = m.step(3.0, 0.0, 9.80665, 0.0)
    assert math.sqrt(t.transient) == pytest.approx(0.1 * math.exp(-1.0))
    assert t.unhealthy
    for _ in range(100):
        t = m.step(0.5, 0.0, 9.80665, 0.0)
    assert t.transient == 0.0 and not t.unhealthy


# -- accuracy -------------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_consensus_at_most_the_better_on_the_bundled_bags(tmp_path):
    from riann_ros.cli.evaluate import main

    bags = sorted(str(p) for p in (ROOT / "bags").glob("*.mcap"))
    assert main([*bags, "-e", "riann,vqf,consensus", "-s", "as-recorded", "-p", "none", "-p", "bias:3,3,0",
                 "--use-mag", "false", "--no-plots", "-q", "--out", str(tmp_path / "out")]) == 0
    import json

    rows = json.loads((tmp_path / "out" / "results.json").read_text())["results"]
    for cond in ("none", "bias:3,3,0"):
        mean = {e: np.mean([r["rmse_deg"] for r in rows if (r["estimator"], r["perturbation"]) == (e, cond)])
                for e in ("riann", "vqf", "consensus")}
        assert mean["consensus"] <= min(mean["riann"], mean["vqf"]), (cond, mean)


@pytest.mark.slow
@pytest.mark.broad
@pytest.mark.parametrize("trial", ["21", "30"])
def test_consensus_beats_both_on_broad_trials(broad_trial, trial):
    rec = broad_trial(trial)
    got = {}
    for name in ("riann", "vqf", "consensus"):
        q, ok = EstimatorStream(create(name), GateConfig(nominal_rate=rec.rate_hz)).process_batch(
            rec.stamps_ns + 1_700_000_000_000_000_000, rec.acc, rec.gyr)  # BROAD starts at 0: "unstamped"
        assert ok.all()
        got[name] = rmse(rec, q)
    assert got["consensus"] < min(got["riann"], got["vqf"]), got


def test_consensus_yaml_lists_every_estimator_parameter_with_its_default():
    yaml = pytest.importorskip("yaml")
    params = yaml.safe_load((ROOT / "config" / "consensus.yaml").read_text())["/**"]["ros__parameters"]
    expected = {p.name: list(p.default) if isinstance(p.default, tuple) else p.default
                for p in ConsensusEstimator.PARAMS}
    assert params == expected
    assert all(type(params[k]) is type(v) for k, v in expected.items())


@pytest.mark.parametrize("lag_ms", [-4.0, 3.0, 8.0])
def test_the_relative_lag_is_fitted_from_the_two_opinions_and_moves_vqf_to_riann_s_instant(lag_ms):
    """VQF's opinion as RIANN's of τ earlier while the sensor swings about two axes: the online fit finds τ, and VQF
    moved by it agrees with RIANN far better than before; at rest nothing is fitted (τ stays 0)."""
    from riann_ros.estimators.consensus_lag import RelativeLag
    from riann_ros.rotations import gravity

    rate, tau = 200.0, lag_ms * 1e-3
    t = np.arange(0.0, 60.0, 1.0 / rate)

    def attitude(tt: np.ndarray) -> np.ndarray:
        return quat.multiply(quat.from_rotvec(np.column_stack([0.6 * np.sin(1.3 * tt), np.zeros_like(tt),
                                                               np.zeros_like(tt)])),
                             quat.from_rotvec(np.column_stack([np.zeros_like(tt), 0.5 * np.sin(0.7 * tt + 1.0),
                                                               np.zeros_like(tt)])))

    q_r, q_v = attitude(t), attitude(t - tau)
    h = 1e-4  # the body rate from the attitude: ω = 2 (q⁻¹ q̇), vector part
    dq = quat.multiply(quat.conjugate(q_r), attitude(t + h))
    w = 2.0 * dq[:, 1:] / h
    lag = RelativeLag()
    before, after = [], []
    for i in range(len(t)):
        qr, qv, wi = tuple(q_r[i]), tuple(q_v[i]), tuple(w[i])
        lag.step(gravity(qr), gravity(qv), wi, 1.0 / rate, 30.0)
        if t[i] > 40.0:
            before.append(np.linalg.norm(np.subtract(gravity(qv), gravity(qr))))
            after.append(np.linalg.norm(np.subtract(gravity(lag.move(qv, wi)), gravity(qr))))
    assert lag.tau_s == pytest.approx(tau, rel=0.1)
    assert np.sqrt(np.mean(np.square(after))) < 0.2 * np.sqrt(np.mean(np.square(before)))
    still = RelativeLag()
    for _ in range(2000):
        still.step((0.0, 0.0, 1.0), (0.001, 0.0, 1.0), (0.0, 0.0, 0.0), 0.005, 30.0)
    assert still.tau_s == 0.0
