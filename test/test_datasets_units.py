"""The unit checks of riann_ros.datasets.units: rate, gravity, gyro and magnetic field against the units they were
read in, and what each check suggests."""

from __future__ import annotations

import numpy as np
import pytest


def _imu(rate: float = 200.0, n: int = 1000, acc_scale: float = 1.0, gyr_scale: float = 1.0, seed: int = 0):
    """Half rest (gravity on z, gyro noise), half rotation at up to ~6 rad/s; units scaled by the arguments."""
    from riann_ros.recording import Recording

    rng = np.random.default_rng(seed)
    gyr = rng.normal(0, 0.01, (n, 3))
    gyr[n // 2 :] += 6.0 * np.sin(np.linspace(0, 20, n - n // 2))[:, None] * [1, 0.5, 0.2]
    acc = rng.normal(0, 0.05, (n, 3)) + np.array([0, 0, 9.81])
    stamps = np.round(np.arange(n) * 1e9 / rate).astype(np.int64)
    return Recording(stamps_ns=stamps, acc=acc * acc_scale, gyr=gyr * gyr_scale)


def test_units_plausible_inputs_pass() -> None:
    from riann_ros.datasets.synthetic import generate
    from riann_ros.datasets.units import check_units

    assert check_units(_imu()) == []
    for rate in (1.0, 10.0, 1000.0, 10_000.0):  # the range ends are plausible
        assert check_units(_imu(rate=rate)) == [], rate
    for motion in ("combined", "rotation", "translation"):
        for rate in (50.0, 1000.0):
            assert check_units(generate(rate=rate, duration=30, seed=5, motion=motion)) == [], (motion, rate)
    # fast, large motion: the median |acc| over all samples is ~19 m/s², at rest it is gravity
    assert check_units(generate(rate=200, duration=30, seed=1, speed=3, max_tilt_deg=90)) == []


@pytest.mark.broad
def test_units_broad_trials_pass() -> None:
    from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad
    from riann_ros.datasets.units import check_units

    d = find_broad_dir()
    if d is None:
        pytest.skip("BROAD not found")
    for f in broad_files(d):
        assert check_units(read_broad(f)) == [], f.name


@pytest.mark.parametrize(
    ("rate", "time_unit", "suggest"),
    [(0.2, "s", "ms"), (0.0002, "s", "us"), (0.0000002, "s", "ns"), (200_000.0, "ms", "s"), (2e5, "ns", "us")],
)
def test_units_rate_suggests_the_unit_that_fits(rate: float, time_unit: str, suggest: str) -> None:
    from riann_ros.datasets.units import check_units

    (f,) = check_units(_imu(rate=rate), time_unit=time_unit)
    assert (f.check, f.flag, f.suggest, f.unit) == ("rate", "--time-unit", suggest, time_unit)
    assert f.value == pytest.approx(rate) and f"looks like {suggest} stamps read as {time_unit}" in str(f)


def test_units_rate_both_candidates_and_none() -> None:
    from riann_ros.datasets.units import check_units

    # a 2 Hz log in ms read as s: 0.002 Hz; ms → 2 Hz and us → 2 kHz are both in range: the nearer to 200 Hz wins
    (f,) = check_units(_imu(rate=0.002, n=50))
    assert f.suggest == "us"
    (f,) = check_units(_imu(rate=0.2, n=50), time_unit="ns")  # already the finest unit: nothing fits
    assert f.suggest is None and "no time unit" in str(f)
    assert check_units(_imu(n=1)) == []  # one sample: no rate to check


def test_units_gravity_and_gyro() -> None:
    from riann_ros.constants import GRAVITY
    from riann_ros.datasets.units import check_units

    (f,) = check_units(_imu(acc_scale=1 / GRAVITY))  # g read as m/s²
    assert (f.check, f.flag, f.suggest) == ("acc", "--acc-unit", "g") and f.value == pytest.approx(1.0, abs=0.01)
    assert "samples at rest" in str(f)
    (f,) = check_units(_imu(acc_scale=GRAVITY), acc_unit="g")  # m/s² data read as g (×9.81 when read)
    assert f.suggest == "m/s2"
    (f,) = check_units(_imu(acc_scale=1000 / GRAVITY))  # mg: no supported unit
    assert f.suggest is None and "implausible" in str(f)
    (f,) = check_units(_imu(gyr_scale=180 / np.pi))  # deg/s read as rad/s; rest found with the corrected gyro
    assert (f.check, f.flag, f.suggest) == ("gyr", "--gyr-unit", "deg/s") and f.value > 35
    (f,) = check_units(_imu(gyr_scale=1000 * 180 / np.pi))  # mdps (ST's unit) read as rad/s
    assert f.suggest == "mdeg/s"
    (f,) = check_units(_imu(gyr_scale=1e6 * 180 / np.pi))  # µdps: too large in every unit
    assert f.suggest is None


def test_units_rest_fallback_and_unit_tables() -> None:
    from riann_ros.datasets import units
    from riann_ros.datasets.csvfile import ACC_UNITS, GYR_UNITS, TIME_UNITS

    rec = _imu()
    rec.gyr[:] = 1.0  # never at rest: the median is over all samples
    rec.acc[:] = [0, 0, 1.0]
    (f,) = units.check_units(rec)
    assert "all 1000 samples (none at rest)" in str(f) and f.suggest == "g"
    rec.acc[:] = [0, 0, 9.81 * units.GRAVITY]
    rec.meta.update(acc_unit="g")  # the CSV reader records the units it read: used by default
    assert units.check_units(rec)[0].suggest == "m/s2"
    # every unit the CSV reader accepts is known to the checks, with the same scale
    tables = ((TIME_UNITS, units.TIME_SCALES), (ACC_UNITS, units.ACC_SCALES), (GYR_UNITS, units.GYR_SCALES))
    for table, scales in tables:
        for name, scale in table.items():
            assert scales[units.canonical_unit(name, scales)] == pytest.approx(scale), name


@pytest.mark.parametrize(("scale", "unit", "suggest"), [(1.0, "T", None), (1e4, "T", "G"), (1e6, "T", "uT"),
                                                        (1e9, "T", "nT"), (1e-2, "uT", "G")])
def test_units_magnetic_field(scale: float, unit: str, suggest: str | None) -> None:
    """Earth's field (45 µT) is plausible in tesla; the same numbers in another unit are named."""
    from riann_ros.datasets.units import check_units

    rec = _imu()
    rng = np.random.default_rng(0)
    d = rng.normal(size=(len(rec), 3))
    rec.mag = 45e-6 * d / np.linalg.norm(d, axis=1, keepdims=True) * scale
    rec.meta["mag_unit"] = unit
    found = [f for f in check_units(rec) if f.check == "mag"]
    if scale == 1.0:
        assert found == []
    else:
        assert len(found) == 1 and found[0].option == "mag_unit"
        assert found[0].suggest == suggest, found[0]


@pytest.mark.broad
def test_broad_magnetometer_in_tesla() -> None:
    from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad

    d = find_broad_dir()
    if d is None:
        pytest.skip("BROAD not found")
    rec = read_broad(broad_files(d)[0])
    assert rec.mag is not None and rec.mag.shape == (len(rec), 3)
    assert 25e-6 < np.median(np.linalg.norm(rec.mag, axis=1)) < 65e-6


# -- the gyro against the accelerometer (riann_ros.datasets.gyro_tilt, units.check_gyro_tilt) --------------------


def _slow_tilts(seed: int = 1):
    """Two minutes of slow tilting (roll and pitch up to ±60°, 99th percentile of |gyr| below 35 °/s, so the range
    check cannot see a deg/s gyro), rest phases between, a 1.1 °/s gyro bias and white noise, in rad/s and m/s²."""
    from riann_ros.datasets.synthetic import generate

    rec = generate(rate=100, duration=120, seed=seed, motion="rotation", speed=0.1, bias=0.02, max_tilt_deg=60)
    assert np.percentile(np.linalg.norm(rec.gyr, axis=1), 99) < 35 * DEG  # slow: the range check cannot tell
    return rec


DEG = np.pi / 180


def test_gyro_tilt_ratio_is_the_unit_factor_whatever_the_accelerometer_unit() -> None:
    """Per tilt the gyro turns the gravity direction as far as the accelerometer sees it turn (ratio 1), 57.3 times as
    far when deg/s are read as rad/s; the accelerometer's scale does not enter (only its direction does)."""
    from riann_ros.datasets.gyro_tilt import measure

    rec = _slow_tilts()
    tilts = measure(rec.stamps_ns, rec.acc, rec.gyr)
    assert len(tilts) >= 10 and np.all(tilts.tilt_deg >= 15)
    assert np.median(tilts.ratio) == pytest.approx(1.0, rel=0.1)
    deg = measure(rec.stamps_ns, rec.acc, rec.gyr / DEG)
    np.testing.assert_allclose(deg.ratio, tilts.ratio / DEG, rtol=1e-9)
    in_g = measure(rec.stamps_ns, rec.acc / 9.80665, rec.gyr)
    np.testing.assert_allclose(in_g.ratio, tilts.ratio, rtol=1e-9)
    assert tilts.still_rate == pytest.approx(0.02, rel=0.5)  # the bias, seen while still


@pytest.mark.parametrize(("gyr_scale", "stated", "suggest"), [
    (1 / DEG, "rad/s", "deg/s"),  # deg/s read as rad/s: 57.3× too large, slow, so within the range check's bound
    (DEG, "deg/s", "rad/s"),  # rad/s read as deg/s: 57.3× too small
    (1000.0, "rad/s", "mrad/s"),  # mrad/s read as rad/s (the range check says deg/s; the tilt check measures 1000)
    (1000.0, "deg/s", "mdeg/s"),  # mdeg/s (mdps, ST's unit) read as deg/s
    (1.0, "rad/s", None),
    (1.0, "deg/s", None),  # deg/s data read as deg/s: the recording (as read) is in rad/s already
])
@pytest.mark.parametrize("acc", ["m/s2", "g", "g read as m/s2"])
def test_gyro_unit_found_from_the_tilts(gyr_scale: float, stated: str, suggest: str | None, acc: str) -> None:
    """The unit whose factor the tilts show is named, whatever the accelerometer's unit; a wrong accelerometer unit
    is named beside it."""
    from riann_ros.datasets.units import check_units

    rec = _slow_tilts()
    rec.gyr = rec.gyr * gyr_scale
    acc_unit = "g" if acc == "g" else "m/s2"  # (a recording holds the values as read: g read as g are m/s² here)
    if acc == "g read as m/s2":
        rec.acc = rec.acc / 9.80665
    found = check_units(rec, gyr_unit=stated, acc_unit=acc_unit)
    gyr = [f for f in found if f.check == "gyr"]
    if suggest is None:
        assert gyr == []
    else:
        (f,) = gyr
        assert (f.flag, f.suggest, f.unit) == ("--gyr-unit", suggest, stated)
        assert "turns the gravity direction" in str(f) and f"looks like {suggest} read as {stated}" in str(f)
        factor = {"rad/s": 1.0, "deg/s": DEG, "mrad/s": 1e-3, "mdeg/s": 1e-3 * DEG}
        assert f.value == pytest.approx(factor[stated] / factor[suggest], rel=0.1)  # the measured ratio
    assert [f.suggest for f in found if f.check == "acc"] == (["g"] if acc == "g read as m/s2" else [])


def test_gyro_tilt_says_nothing_where_the_data_cannot_show_it() -> None:
    """No judgement without tilts: a deg/s gyro turning slowly about the vertical only (the gravity direction does
    not move), and tilts made by linear acceleration alone (a well-read deg/s gyro that shows only its bias beside
    them is not taken for rad/s read as deg/s)."""
    from riann_ros.datasets.units import check_units
    from riann_ros.recording import Recording

    rng = np.random.default_rng(0)
    t = np.arange(12000) / 100.0
    stamps = np.round(t * 1e9).astype(np.int64)
    yaw_rate = 0.5 * np.sin(2 * np.pi * t / 20)  # rad/s about the vertical, ≤ 29 °/s
    gyr = np.column_stack([0 * t, 0 * t, yaw_rate]) / DEG + rng.normal(0, 0.05, (len(t), 3))  # deg/s as rad/s
    acc = np.array([0, 0, 9.81]) + rng.normal(0, 0.05, (len(t), 3))
    assert check_units(Recording(stamps, acc, gyr)) == []  # nothing to see: said nothing
    # back-and-forth horizontal accelerations of 0.3 g in bursts (still between), no rotation, 0.3 °/s bias
    burst = (np.sin(2 * np.pi * t / 10) > 0) * 0.3 * 9.81 * np.sin(2 * np.pi * t)
    acc = np.column_stack([burst, 0 * t, 9.81 + 0 * t]) + rng.normal(0, 0.05, (len(t), 3))
    gyr = np.array([0.0, 0.005, 0.0]) + rng.normal(0, 0.005, (len(t), 3))
    for stated in ("deg/s", "rad/s"):
        assert check_units(Recording(stamps, acc, gyr), gyr_unit=stated) == [], stated


@pytest.mark.broad
def test_gyro_tilt_on_broad_trials() -> None:
    """Every BROAD trial in its own units: no finding from the tilt check; read as if its rad/s were deg/s
    (57.3× too small), the trials that tilt enough between quasi-static moments name rad/s, none another unit."""
    from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad
    from riann_ros.datasets.units import check_gyro_tilt

    d = find_broad_dir()
    if d is None:
        pytest.skip("BROAD not found")
    named = []
    for f in broad_files(d):
        rec = read_broad(f)
        assert check_gyro_tilt(rec) is None, f.name
        rec.gyr = rec.gyr * DEG
        found = check_gyro_tilt(rec, "deg/s")
        assert found is None or found.suggest == "rad/s", (f.name, found)
        named += [f.name] if found is not None else []
    assert len(named) >= len(broad_files(d)) // 2, named
