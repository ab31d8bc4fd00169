"""The magnetometer calibration on the BROAD trials with injected hard and soft iron, and on a synthetic ground robot.

Usage::

    .venv/bin/python bench/magcal_study.py [--broad DIR] [--trials 01,21] [--model full] [--out /tmp/magcal_study]

Per trial and scenario (recorded field; hard iron 20,0,−10 µT; 35 µT in another direction; 30 µT with a soft iron
of scales 0.85–1.15 and skew 0.05) the online calibration runs causally over the trial, fed the gyro debiased by the
bias front end (VQF's estimate, as the classical filters get it), the magnetometer latency estimated online from the
calibrated field (RIANN's stage 7b), and the reference attitude (for the tilt of the heading σ). It reports the
hard iron's error over time, when the state first turned *calibrated*, the coverage of the calibration's heading σ
(the heading error it causes: the calibrated field's heading minus the recorded field's, both tilt-compensated with
the reference attitude) and the field heading's error against the reference heading (recorded field, raw field,
calibrated field: whole trial, after convergence, from 60 s). The offline fit runs on the whole trial too. Figures
go to stdout (a markdown table) and ``OUT/magcal_study.json``; nothing BROAD-derived is written into the repository.

The ground robot (synthetic, :func:`riann_ros.magcal.synthetic.ground_robot`): turns about the vertical only, with
rest and straight phases; the hard iron across the axis must converge, the component along it stay at its prior,
and nothing move at rest or while driving straight.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad
from riann_ros.estimators.bias import GyroBiasFrontEnd
from riann_ros.magcal.latency import LatencyEstimator
from riann_ros.magcal.offline import fit_recording
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import UT
from riann_ros.magcal.synthetic import FIELD_ENU_T, distort, ground_robot
from riann_ros.rotations import rotate

SOFT = np.array([[1.15, 0.05, 0.0], [0.0, 0.85, 0.05], [0.05, 0.0, 1.0]])  # D: scales 0.85–1.15, skew 0.05
D35 = np.array([-20.0, 25.0, 15.0]) / np.linalg.norm([-20.0, 25.0, 15.0]) * 35.0
SCENARIOS = {  # name: (hard iron µT, distortion D: raw = D m + h)
    "recorded": (np.zeros(3), np.eye(3)),
    "offset_20_0_-10": (np.array([20.0, 0.0, -10.0]), np.eye(3)),
    "offset_35": (D35, np.eye(3)),
    "offset_30_soft": (D35 * 30.0 / 35.0, SOFT),
}


def wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def field_heading(q: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The heading error of a field tilt-compensated with ``q`` (ENU, y north): atan2(m_w,x, m_w,y)."""
    mw = quat.rotate(q, m)
    return np.arctan2(mw[:, 0], mw[:, 1])


def prepare(path: Path) -> dict:
    rec = read_broad(path)
    dt = rec.dt
    fe = GyroBiasFrontEnd(float(dt[0]))
    gyr = rec.gyr - fe.update_batch(rec.acc, rec.gyr, dt)
    q = rec.quat_ref.copy()
    valid = np.isfinite(q).all(axis=1)
    idx = np.maximum.accumulate(np.where(valid, np.arange(len(q)), 0))
    q = q[idx]
    q[~np.isfinite(q).all(axis=1)] = (1.0, 0.0, 0.0, 0.0)
    d = {"rec": rec, "gyr": gyr, "dt": dt, "q": q, "score": rec.score_mask & valid, "t": rec.t}
    return d


def reference(d: dict, model: str, delay_s: float) -> np.ndarray:
    """The trial's own best calibration of its recorded field (offline, all of it): the recorded field through it."""
    fit = fit_recording(d["gyr"], d["dt"], d["rec"].mag, soft_iron_model=model, delay_s=delay_s, acc=d["rec"].acc)
    c = fit.calibration
    return (d["rec"].mag - np.asarray(c.hard_iron_t)) @ np.asarray(c.soft_iron).reshape(3, 3).T


def run_online(d: dict, raw_t: np.ndarray, model: str) -> dict:
    gyr, dt, q = d["gyr"], d["dt"], d["q"]
    rv = gyr * dt[:, None]
    inc = quat.from_rotvec(rv).tolist()
    rvl, dtl, ql, rawl = rv.tolist(), dt.tolist(), q.tolist(), raw_t.tolist()
    cal = OnlineMagCalibrator(soft_iron_model=model)  # type: ignore[arg-type]
    lat = LatencyEstimator()
    n = len(dt)
    u_out = np.full((n, 3), np.nan)
    sd = np.full(n, np.nan)
    hist = []
    seen = 0
    t0 = time.perf_counter()
    for i in range(n):
        delay = lat.delay(0.0)
        qi = tuple(ql[i])
        u = cal.update(tuple(inc[i]), dtl[i], tuple(rawl[i]), delay, qi)  # type: ignore[arg-type]
        lat.add(tuple(inc[i]), tuple(rvl[i]), dtl[i], u)  # type: ignore[arg-type]
        if u is not None:
            u_out[i] = u
            sd[i] = cal.heading_sd_rad(qi, rotate(qi, u))  # type: ignore[arg-type]
        if cal.windows != seen:
            seen = cal.windows
            c = cal.calibration()
            hist.append((float(d["t"][i]), *c.hard_iron_t, *c.hard_iron_sd_t))
    el = time.perf_counter() - t0
    return {"u": u_out, "sd": sd, "hist": np.array(hist).reshape(-1, 7), "cal": cal, "us": 1e6 * el / n,
            "delay_ms": 1e3 * lat.delay(0.0)}


def rmse_deg(e: np.ndarray) -> float:
    return float(np.degrees(np.sqrt(np.mean(e * e)))) if len(e) else float("nan")


def hard_iron_error_at(hist: np.ndarray, h_true: np.ndarray, t: float) -> float:
    rows = hist[hist[:, 0] <= t]
    h = rows[-1, 1:4] / UT if len(rows) else np.zeros(3)
    return float(np.linalg.norm(h - h_true))


def coverage(delta: np.ndarray, sd: np.ndarray) -> dict:
    z = delta / np.maximum(sd, 1e-9)
    return {"cover_1sd": float(np.mean(np.abs(z) <= 1.0)), "cover_2sd": float(np.mean(np.abs(z) <= 2.0)),
            "nees": float(np.mean(z * z)), "n": len(z)}


def study_trial(d: dict, name: str, scen: str, model: str) -> dict:
    h_true, dist = SCENARIOS[scen]
    rec = d["rec"]
    raw = rec.mag @ dist.T + h_true * UT
    on = run_online(d, raw, model)
    cal = on["cal"]
    t, q, ok = d["t"], d["q"], d["score"]
    e_rec = field_heading(q, rec.mag)
    e_raw = field_heading(q, raw)
    e_cal = field_heading(q, np.nan_to_num(on["u"]))
    delta = wrap(e_cal - e_rec)  # the heading error the calibration causes (against the recorded field's)
    if "u_ref" not in d:
        d["u_ref"] = reference(d, model, on["delay_ms"] * 1e-3)
    delta_ref = wrap(e_cal - field_heading(q, d["u_ref"]))  # against the trial's own offline calibration
    has = ok & np.isfinite(on["sd"])
    tc = cal.converged_after_s
    after = has & (t >= tc) if tc is not None else np.zeros_like(has)
    c = cal.calibration()
    s_est = np.array(c.soft_iron).reshape(3, 3)
    s_true = np.linalg.inv(dist)
    off = fit_recording(d["gyr"], d["dt"], raw, soft_iron_model=model, delay_s=on["delay_ms"] * 1e-3, acc=rec.acc)
    s_off = np.array(off.calibration.soft_iron).reshape(3, 3)

    def s_err(s: np.ndarray) -> float:  # the largest entry error after the unobservable common scale
        k = float(np.sum(s * s_true) / np.sum(s * s))
        return float(np.abs(k * s - s_true).max())

    return {
        "trial": name, "scenario": scen, "duration_s": float(t[-1]), "converged_s": tc,
        "h_err_ut": {f"{s}s": hard_iron_error_at(on["hist"], h_true, s) for s in (10, 30, 60, 120)}
        | {"end": float(np.linalg.norm(np.array(c.hard_iron_t) / UT - h_true))},
        "h_end_ut": [v / UT for v in c.hard_iron_t], "h_sd_end_ut": [v / UT for v in c.hard_iron_sd_t],
        "soft_err_end": s_err(s_est),
        "windows": cal.windows, "rejected": cal.rejected, "unit_weight": cal.unit_weight,
        "vs_recorded": coverage(delta[has], on["sd"][has]), "vs_offline": coverage(delta_ref[has], on["sd"][has]),
        "cal_err_rmse_deg": rmse_deg(delta[has]), "cal_sd_rms_deg": rmse_deg(on["sd"][has]),
        "heading_rmse_deg": {"recorded": rmse_deg(wrap(e_rec[ok])), "raw": rmse_deg(wrap(e_raw[ok])),
                             "calibrated": rmse_deg(wrap(e_cal[has])),
                             "calibrated_after_conv": rmse_deg(wrap(e_cal[after])),
                             "recorded_after_conv": rmse_deg(wrap(e_rec[after])),
                             "calibrated_from_60s": rmse_deg(wrap(e_cal[has & (t >= 60)])),
                             "recorded_from_60s": rmse_deg(wrap(e_rec[ok & (t >= 60)]))},
        "offline_h_ut": [v / UT for v in off.calibration.hard_iron_t],
        "offline_h_err_ut": float(np.linalg.norm(np.array(off.calibration.hard_iron_t) / UT - h_true)),
        "offline_h_sd_ut": [v / UT for v in off.calibration.hard_iron_sd_t], "offline_soft_err": s_err(s_off),
        "offline_residual_rms_ut": off.residual_rms_ut, "offline_outliers": off.outliers,
        "delay_ms": on["delay_ms"], "us_per_sample": on["us"],
    }


def ground_robot_study(model: str) -> dict:
    """Turns about the vertical (sensor tilted 10° on its mount), then rest, then straight driving."""
    phases = [("rest", 5.0, 0.0)] + [("turn", 6.0, 30.0), ("straight", 4.0, 0.0), ("turn", 6.0, -45.0)] * 8
    phases += [("rest", 30.0, 0.0), ("straight", 30.0, 0.0)]
    rec = ground_robot(phases, rate_hz=100.0, mount_rpy_deg=(10.0, -5.0, 30.0), gyr_noise=0.003, seed=1)
    h = np.array([20.0, 0.0, -10.0])
    raw = distort(rec.quat_ref, h * UT, noise_t=0.4e-6, seed=2)
    cal = OnlineMagCalibrator(soft_iron_model=model)  # type: ignore[arg-type]
    inc = quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()
    t_turns = sum(p[1] for p in phases[:-2])
    snap = None
    axis = quat.rotate(quat.conjugate(rec.quat_ref[0]), np.array([0.0, 0.0, 1.0]))
    for i in range(len(rec)):
        qi = tuple(rec.quat_ref[i])
        u = cal.update(tuple(inc[i]), float(rec.dt[i]), tuple(raw[i]), 0.0, qi)  # type: ignore[arg-type]
        if snap is None and rec.t[i] >= t_turns:
            snap = cal.calibration()
    end = cal.calibration()
    assert snap is not None and u is not None
    e = float(np.degrees(abs(wrap(field_heading(rec.quat_ref[-1:], np.array([u]))[0:1]))[0]))
    h_snap = np.array(snap.hard_iron_t) / UT
    h_end = np.array(end.hard_iron_t) / UT
    return {"h_true_ut": h.tolist(), "h_after_turns_ut": h_snap.tolist(), "h_end_ut": h_end.tolist(),
            "moved_in_rest_and_straight_ut": float(np.linalg.norm(h_end - h_snap)),
            "axis_sensor": axis.tolist(), "along_axis_err_ut": float(abs((h_snap - h) @ axis)),
            "across_axis_err_ut": float(np.linalg.norm((h_snap - h) - ((h_snap - h) @ axis) * axis)),
            "state": end.state, "converged_s": end.converged_after_s, "final_heading_err_deg": e,
            "field": list(FIELD_ENU_T)}


def table(rows: list[dict]) -> str:
    head = ("| trial | scenario | conv. s | h err 30 s / 60 s / end µT | σ_h end µT | 2σ cover / NEES vs recorded "
            "| vs offline | heading RMSE ° rec / raw / cal / cal after conv / cal from 60 s (rec from 60 s) "
            "| offline h µT / S % |")
    out = [head, "|" + "---|" * 9]
    for r in rows:
        h, hd, a, b = r["h_err_ut"], r["heading_rmse_deg"], r["vs_recorded"], r["vs_offline"]
        conv = f"{r['converged_s']:.0f}" if r["converged_s"] is not None else "—"
        out.append(f"| {r['trial'][:2]} | {r['scenario']} | {conv} | {h['30s']:.2f} / {h['60s']:.2f} / "
                   f"{h['end']:.2f} | {max(r['h_sd_end_ut']):.2f} | {100 * a['cover_2sd']:.0f} % / {a['nees']:.2f} "
                   f"| {100 * b['cover_2sd']:.0f} % / {b['nees']:.2f} | {hd['recorded']:.2f} / {hd['raw']:.1f} / "
                   f"{hd['calibrated']:.2f} / {hd['calibrated_after_conv']:.2f} / {hd['calibrated_from_60s']:.2f} "
                   f"({hd['recorded_from_60s']:.2f}) | {r['offline_h_err_ut']:.2f} / "
                   f"{100 * r['offline_soft_err']:.2f} |")
    return "\n".join(out)


def pooled(rows: list[dict]) -> str:
    """Per scenario over the trials: coverage pooled by samples, means of the rest. Trial 33 is left out of the
    coverage against its own offline calibration: that is the calibration without the magnet attached for 55 s of
    its motion, while the online one rightly holds the magnet as hard iron while it is attached."""
    out = ["| scenario | trials converged | conv. s mean | h err end µT mean / worst | 2σ cover / NEES vs recorded "
           "(undisturbed trials) | vs offline (all but 33) | heading RMSE ° cal from 60 s / rec from 60 s (mean) "
           "| offline h err µT mean / worst |", "|" + "---|" * 8]
    for scen in dict.fromkeys(r["scenario"] for r in rows):
        rs = [r for r in rows if r["scenario"] == scen]
        und = [r for r in rs if r["trial"][:2] < "24"]

        def pool(sel: list[dict], key: str) -> tuple[float, float]:
            n = sum(r[key]["n"] for r in sel)
            if not n:
                return float("nan"), float("nan")
            return (sum(r[key]["cover_2sd"] * r[key]["n"] for r in sel) / n,
                    sum(r[key]["nees"] * r[key]["n"] for r in sel) / n)

        conv = [r["converged_s"] for r in rs if r["converged_s"] is not None]
        he = [r["h_err_ut"]["end"] for r in rs]
        oe = [r["offline_h_err_ut"] for r in rs]
        c1, n1 = pool(und, "vs_recorded")
        c2, n2 = pool([r for r in rs if not r["trial"].startswith("33")], "vs_offline")
        hc = np.nanmean([r["heading_rmse_deg"]["calibrated_from_60s"] for r in rs])
        hr = np.nanmean([r["heading_rmse_deg"]["recorded_from_60s"] for r in rs])
        out.append(f"| {scen} | {len(conv)}/{len(rs)} | {np.mean(conv) if conv else float('nan'):.0f} | "
                   f"{np.mean(he):.2f} / {np.max(he):.2f} | {100 * c1:.0f} % / {n1:.2f} | {100 * c2:.0f} % / "
                   f"{n2:.2f} | {hc:.2f} / {hr:.2f} | {np.mean(oe):.2f} / {np.max(oe):.2f} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--broad", default=None, help="BROAD folder (default: RIANN_BROAD_DIR or ../shared/datasets/broad)")
    ap.add_argument("--trials", default="", help="comma-separated trial numbers (default: all)")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS), help="comma-separated scenario names")
    ap.add_argument("--model", default="full", choices=("full", "symmetric", "none"), help="soft-iron model")
    ap.add_argument("--out", default="/tmp/magcal_study", help="folder for magcal_study.json")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    result: dict = {"model": a.model, "ground_robot": ground_robot_study(a.model)}
    print("ground robot:", json.dumps(result["ground_robot"], indent=1))
    broad = Path(a.broad) if a.broad else find_broad_dir()
    rows = []
    if broad is not None:
        want = [s for s in a.trials.split(",") if s]
        for p in broad_files(broad):
            if want and p.name[:2] not in want:
                continue
            d = prepare(p)
            for scen in a.scenarios.split(","):
                r = study_trial(d, p.stem, scen, a.model)
                rows.append(r)
                print(table([r]).splitlines()[-1], flush=True)
    result["trials"] = rows
    (out / "magcal_study.json").write_text(json.dumps(result, indent=1))
    if rows:
        print(table(rows))
        print()
        print(pooled(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
