"""Reader for BROAD trials (Laidig et al. 2021, CC BY 4.0), ``.hdf5`` and ``.mat`` files.

Keys: ``imu_acc`` (N,3) m/s², ``imu_gyr`` (N,3) rad/s, ``opt_quat`` (N,4) w,x,y,z sensor→ENU with NaN
rows, ``movement`` (N,) scoring mask, ``sampling_rate`` (HDF5 attribute or .mat variable); optional
``imu_mag`` (N,3) magnetic field in µT, read into :attr:`Recording.mag` in tesla (REP-145).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from riann_ros.constants import NS_PER_S
from riann_ros.recording import Recording

#: the attribution CC BY 4.0 asks for (authors, title, source, licence and its address), carried into every bag
#: made from a trial (``/dataset/info`` ``source``)
SOURCE = (
    'BROAD: D. Laidig, M. Caruso, A. Cereatti, T. Seel, "BROAD — A Benchmark for Robust Inertial Orientation '
    'Estimation", Data 6(7):72, 2021, https://doi.org/10.3390/data6070072; licensed under CC BY 4.0, '
    "https://creativecommons.org/licenses/by/4.0/"
)
REQUIRED = ("imu_acc", "imu_gyr", "opt_quat", "movement")
OPTIONAL = ("imu_mag",)
MICROTESLA = 1e-6  # T per µT


def _read_hdf5(path: Path) -> dict[str, np.ndarray]:
    import h5py

    with h5py.File(path, "r") as f:
        missing = [k for k in REQUIRED if k not in f]
        if missing:
            raise ValueError(f"{path}: missing BROAD key(s) {', '.join(missing)}")
        data = {k: np.asarray(f[k][()]) for k in (*REQUIRED, *OPTIONAL) if k in f}
        rate = f.attrs.get("sampling_rate", f["sampling_rate"][()] if "sampling_rate" in f else None)
    if rate is None:
        raise ValueError(f"{path}: no sampling_rate attribute")
    data["sampling_rate"] = np.asarray(rate, dtype=float)
    return data


def _read_mat(path: Path) -> dict[str, np.ndarray]:
    import scipy.io

    m = scipy.io.loadmat(path)
    missing = [k for k in (*REQUIRED, "sampling_rate") if k not in m]
    if missing:
        raise ValueError(f"{path}: missing BROAD variable(s) {', '.join(missing)}")
    return {k: np.asarray(m[k]) for k in (*REQUIRED, *OPTIONAL, "sampling_rate") if k in m}


def read_broad(path: str | os.PathLike[str]) -> Recording:
    """Read one BROAD trial file into a :class:`Recording` (stamps from the sampling rate)."""
    path = Path(path)
    if path.suffix.lower() in (".hdf5", ".h5"):
        d = _read_hdf5(path)
    elif path.suffix.lower() == ".mat":
        d = _read_mat(path)
    else:
        raise ValueError(f"{path}: not a BROAD file (expected .hdf5 or .mat)")
    acc = np.asarray(d["imu_acc"], dtype=np.float64)
    gyr = np.asarray(d["imu_gyr"], dtype=np.float64)
    q = np.asarray(d["opt_quat"], dtype=np.float64)
    mask = np.asarray(d["movement"]).reshape(-1).astype(bool)
    rate = float(np.asarray(d["sampling_rate"]).reshape(-1)[0])
    n = len(acc)
    if not (gyr.shape == (n, 3) and acc.shape == (n, 3) and q.shape == (n, 4) and mask.shape == (n,)):
        raise ValueError(f"{path}: inconsistent array shapes acc {acc.shape} gyr {gyr.shape} quat {q.shape}")
    mag = None
    if "imu_mag" in d:
        mag = np.asarray(d["imu_mag"], dtype=np.float64) * MICROTESLA
        if mag.shape != (n, 3):
            raise ValueError(f"{path}: imu_mag has shape {mag.shape}, expected ({n}, 3)")
    stamps = np.round(np.arange(n) * (NS_PER_S / rate)).astype(np.int64)
    q = np.where(np.isfinite(q).all(axis=1, keepdims=True), q, np.nan)
    return Recording(
        stamps_ns=stamps,
        acc=acc,
        gyr=gyr,
        quat_ref=q,
        score_mask=mask,
        name=path.stem,
        dataset="broad",
        source=SOURCE,
        meta={"sampling_rate": repr(rate), "file": path.name},
        mag=mag,
    )


#: where to get BROAD, for a BROAD path that is not there (a clone of the repository holds only trial 21, as a bag)
GET_BROAD = ("BROAD is not part of the repository: download it from https://doi.org/10.3390/data6070072 (the "
             "article's data, CC BY 4.0) into ../shared/datasets/broad, as bags/README.md says")


def missing(path: str | os.PathLike[str]) -> str:
    """The message for an input that does not exist; for what looks like a BROAD trial (a path through
    ``datasets/broad``, an ``.hdf5`` or ``.mat`` file) with where to get BROAD."""
    p = Path(path)
    broad = "datasets/broad" in p.as_posix() or p.suffix.lower() in (".hdf5", ".mat")
    return f"{p}: no such file or directory" + (f" ({GET_BROAD})" if broad else "")


def find_broad_dir() -> Path | None:
    """The BROAD folder from ``$RIANN_BROAD_DIR`` or ``../shared/datasets/broad``; None when absent."""
    env = os.environ.get("RIANN_BROAD_DIR")
    candidates = [Path(env)] if env else []
    here = Path(__file__).resolve().parents[2]
    candidates.append(here.parent / "shared" / "datasets" / "broad")
    candidates.append(Path.cwd().parent / "shared" / "datasets" / "broad")
    for c in candidates:
        if c.is_dir() and (any(c.glob("*.hdf5")) or any(c.glob("*.mat"))):
            return c
    return None


def broad_files(directory: str | os.PathLike[str]) -> list[Path]:
    """BROAD trial files in ``directory`` sorted by trial number."""
    d = Path(directory)
    return sorted([*d.glob("*.hdf5"), *d.glob("*.mat")], key=lambda p: p.name)
