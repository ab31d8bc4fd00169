"""One home for the defaults that more than one part of the package uses (ROS-free, no imports).

A default used by one module only stays there; a node parameter's default stays in its ``ParamSpec``.
"""

from __future__ import annotations

from dataclasses import dataclass

#: The sensor frame of a recording, bag or synthetic stream that names none.
IMU_FRAME = "imu_link"

#: s; the time step assumed when a stream gives none (a single sample, or a first dt that is not positive).
FALLBACK_DT_S = 0.01

#: s; a reference or recorded estimate is slerped between two messages at most this far apart and held within half
#: of it (EuRoC ground truth in ``riann-bag-convert --max-gap``, ``riann-bag-eval --max-gap``).
MAX_GAP_S = 0.1

#: deg; one magnetometer heading's error apart from the tilt, fitted by maximum likelihood on the samples whose heading
#: the field corrects in the 12 BROAD trials run in 9D (``bench/fit_uncertainty.py``): RIANN's stage 8 reports it
#: (with the tilt's share and the error the heading carries), the classical filters report it while a field corrects
#: their heading, and the nodes publish it with ``orientation_covariance: constant`` (``mag_yaw_stddev_deg``).
MAG_HEADING_SD_DEG = 2.5

#: deg; the inclination standard deviation (per axis: roll and pitch) the classical filters report and the nodes
#: publish with ``orientation_covariance: constant`` (``roll_pitch_stddev_deg``); the order of RIANN's RMSE on BROAD.
INCLINATION_SD_DEG = 2.0

#: deg; the heading standard deviation while no field ties it (unobservable: gyro drift only; ``yaw_stddev_deg``).
YAW_FREE_SD_DEG = 180.0


@dataclass(frozen=True)
class Synthetic:
    """The synthetic generator's defaults (:func:`riann_ros.datasets.synthetic.generate`,
    ``riann-bag-convert --format synthetic``)."""

    rate: float = 200.0  # Hz
    duration: float = 60.0  # s
    seed: int = 0
    motion: str = "combined"
    bias: float = 0.01  # rad/s, magnitude of a constant gyro bias in a seeded random direction
    gyr_noise: float = 0.004  # rad/s, white-noise standard deviation per sample
    acc_noise: float = 0.03  # m/s², white-noise standard deviation per sample
    max_tilt_deg: float = 60.0  # roll/pitch amplitude scale
    speed: float = 1.0  # frequency scale of the motion


SYNTHETIC = Synthetic()
