"""``riann-mag-calibrate``'s command line: the parser (the run is :mod:`riann_ros.cli.magcal`).

Reference: docs/magnetometer.md, section "Offline". Every option's help is its documentation on the command line.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from riann_ros.magcal.records import SOFT_IRON_MODELS

EXIT_CALIBRATED, EXIT_FAILED, EXIT_USAGE, EXIT_NOT_CONVERGED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="riann-mag-calibrate",
        description="Fit the magnetometer's hard iron (offset) and soft iron (3x3 matrix) from a recorded bag: a "
        "gyro-aided batch fit over all of the recording (a field fixed in the world, seen from a sensor the gyro "
        "says has turned, must turn with it). Prints the estimate with its uncertainty and the residual, writes "
        "the calibration file the nodes load at start (parameter mag_calibration_file), and plots the field "
        "before and after (the sphere) and the heading before and after. Reference: docs/magnetometer.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="The recording must turn the sensor: every window of 45° of rotation (or 15° within 5 s) is one "
        "constraint; the hard iron is observed across the axes the sensor turns about, never along them. A ground "
        "robot that only turns about the vertical calibrates the horizontal components (all the heading needs).\n"
        "exit status: 0 calibrated (file written), 3 written but not calibrated (too little rotation: the state "
        "says converging; the node goes on calibrating from it), 1 nothing to calibrate from or unreadable input "
        "(nothing written), 2 usage error, 130 interrupted",
    )
    p.add_argument("bag", type=Path, metavar="BAG",
                   help="a bag (.mcap, .db3, bag directory) with sensor_msgs/Imu and sensor_msgs/MagneticField "
                   "(--imu-topic, --mag-topic), or a BROAD trial file (.hdf5/.mat)")
    p.add_argument("--out", "-o", type=Path, default=None, metavar="FILE",
                   help="the calibration file to write (YAML in the nodes' parameter names); without it nothing is "
                   "written. An existing calibration file is replaced only with --force; any other file never")
    p.add_argument("--force", action="store_true",
                   help="replace an existing calibration file at --out and existing figures")
    p.add_argument("--plots", type=Path, default=None, metavar="DIR",
                   help="folder for the figures <out stem>_sphere.png and <out stem>_heading.png (default: the "
                   "folder of --out; none without --out)")
    p.add_argument("--no-plots", action="store_true", help="no figures")
    p.add_argument("--imu-topic", default=None, metavar="TOPIC",
                   help="the sensor_msgs/Imu topic (default /imu/data_raw, the converter's layout)")
    p.add_argument("--mag-topic", default=None, metavar="TOPIC",
                   help="the sensor_msgs/MagneticField topic (default /imu/mag, the converter's layout)")
    p.add_argument("--soft-iron-model", choices=SOFT_IRON_MODELS, default="full",
                   help="full (default: scale, skew and the magnetometer's misalignment to the gyro), symmetric, "
                   "or none (hard iron only)")
    p.add_argument("--mag-delay", default="auto", metavar="SECONDS",
                   help="the magnetometer's latency behind the gyro (s, 0 to 0.1: a reading taken this long before "
                   "its stamp says), or auto (default): the latency that leaves the least residual")
    p.add_argument("--prior", type=Path, default=None, metavar="FILE",
                   help="start from a saved calibration file (its estimate and covariance) instead of the unknown "
                   "prior (hard iron 0 ± 50 µT, soft iron identity ± 0.1)")
    return p
