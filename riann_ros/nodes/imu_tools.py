"""imu_tools' parameter names on our nodes, and what the nodes say about names they do not know (ROS-free).

People arrive with parameter files of imu_tools' ``imu_filter_madgwick`` and ``imu_complementary_filter``
(ROS 2 releases, plus ``use_magnetic_field_msg`` of ROS 1). :func:`translate` turns one such name and
value into our parameters where the meaning is the same, converting units (radians to degrees), or
refuses it with the reason. Names that are also ours (``use_mag``, ``world_frame``, ``fixed_frame``,
``publish_tf``, ``reverse_tf``, ``remove_gravity_vector``) need no translation. :func:`unknown_text` names the
closest known name for anything else. The one table of the mapping is in docs/node.md.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

from riann_ros.params import ParamSpec

MADGWICK = "imu_filter_madgwick"
COMPLEMENTARY = "imu_complementary_filter"
BOTH = "imu_tools"


@dataclass
class Translation:
    """What an imu_tools name becomes on one node: our parameters (``name`` or ``name[i]`` for one element of an
    array parameter) with their values, or a refusal; ``note`` says what was done (for the log)."""

    name: str
    source: str
    values: dict[str, Any] = field(default_factory=dict)
    refused: str | None = None
    note: str = ""


def _number(name: str, value: Any) -> float:
    return float(ParamSpec(name, 0.0, "").coerce(value))


def _flag(name: str, value: Any) -> bool:
    return bool(ParamSpec(name, False, "").coerce(value))


def _gain(v: Any, est: str) -> Translation:
    t = Translation("gain", MADGWICK)
    if est == "madgwick":
        g = _number("gain", v)
        t.values = {"beta": g, "beta_marg": g}
        t.note = "the Madgwick gain, for samples without (beta) and with (beta_marg) a magnetometer field"
    else:
        t.refused = f"it is the gain of imu_filter_madgwick's Madgwick filter: {_NO_GAIN[est]}"
    return t


def _zeta(v: Any, est: str) -> Translation:
    t = Translation("zeta", MADGWICK)
    if est == "madgwick" and _number("zeta", v) == 0.0:
        t.note = "0: no gyro drift term, as madgwick_node with gyro_bias_estimation false (its default)"
    elif est == "madgwick":
        t.refused = ("our Madgwick filter has no zeta gyro-drift term; gyro_bias_estimation: true estimates the gyro "
                     "bias in front of the filter instead (VQF's estimator, docs/filters.md)")
    else:
        t.refused = f"it is the gyro drift gain of imu_filter_madgwick's Madgwick filter: {_NO_GAIN[est]}"
    return t


def _mag_bias(axis: int) -> Callable[[Any, str], Translation]:
    def tr(v: Any, est: str) -> Translation:
        name = "mag_bias_" + "xyz"[axis]
        return Translation(name, MADGWICK, {f"mag_hard_iron[{axis}]": _number(name, v)},
                           note="hard-iron offset, tesla, subtracted from the field")
    return tr


def _orientation_stddev(v: Any, est: str) -> Translation:
    t = Translation("orientation_stddev", BOTH)
    s = _number("orientation_stddev", v)
    if s == 0.0:
        t.note = ("0 is imu_tools' 'covariance unknown' (an all-zero matrix); the nodes keep their documented "
                  "roll_pitch_stddev_deg, yaw_stddev_deg and mag_yaw_stddev_deg")
    else:
        d = math.degrees(s)
        t.values = {"roll_pitch_stddev_deg": d, "mag_yaw_stddev_deg": d, "orientation_covariance": "constant"}
        t.note = (f"{s:g} rad = {d:g} deg for roll, pitch and the magnetometer-referenced yaw; yaw_stddev_deg (the "
                  "unobservable 6D heading) stays")
    return t


def _radians_to(ours: str, what: str) -> Callable[[Any, str], Translation]:
    def tr(v: Any, est: str) -> Translation:
        name = ours.removesuffix("_deg")
        d = math.degrees(_number(name, v))
        return Translation(name, MADGWICK, {ours: d}, note=f"{what}, radians -> {ours} = {d:g} deg")
    return tr


DECLINATION_PLAUSIBLE = 0.6  # rad (34°): |declination| beyond this is rare outside polar regions


def _declination(v: Any, est: str) -> Translation:
    """imu_tools' declination is in radians, ours (declination_deg) in degrees: a value that is implausible in
    radians was probably meant in degrees (the unit of ours), and the translation says so."""
    t = _radians_to("declination_deg", "magnetic declination, east positive")(v, est)
    if abs(_number("declination", v)) > DECLINATION_PLAUSIBLE:
        t.note += (f" -- WARNING: {_number('declination', v):g} rad is implausible; declination is in radians "
                   "(imu_tools); for degrees set declination_deg")
    return t


def _constant_dt(v: Any, est: str) -> Translation:
    t = Translation("constant_dt", BOTH)
    dt = _number("constant_dt", v)
    if dt == 0.0:
        t.note = "0: dt from the header stamps, as the nodes always do"
    else:
        t.refused = (f"the nodes always take dt from the header stamps (checked and repaired, docs/node.md, Bad input) "
                     f"and have no fixed dt; nominal_rate: {1.0 / dt:g} sets the dt of the first sample")
    return t


def _debug_topics(v: Any, est: str) -> Translation:
    return Translation("publish_debug_topics", BOTH, {"publish_rpy": _flag("publish_debug_topics", v)},
                       note="roll, pitch, yaw on imu/rpy, in degrees (imu_tools: radians on imu/rpy/filtered)")


def _fixed_flag(name: str, source: str, kept: bool, note: str, refused: str) -> Callable[[Any, str], Translation]:
    """A boolean imu_tools parameter whose value ``kept`` is what the nodes always do (noted) and whose other value
    is refused."""
    def tr(v: Any, est: str) -> Translation:
        if _flag(name, v) == kept:
            return Translation(name, source, note=note)
        return Translation(name, source, refused=refused)
    return tr


def _bias_estimation(v: Any, est: str) -> Translation:
    on = _flag("do_bias_estimation", v)
    if est == "vqf":
        return Translation("do_bias_estimation", COMPLEMENTARY, {"motion_bias_est": on, "rest_bias_est": on},
                           note="VQF's gyro-bias estimation in motion and at rest")
    return Translation("do_bias_estimation", COMPLEMENTARY, {"gyro_bias_estimation": on},
                       note="the gyro-bias estimator in front of the estimator")


def _complementary_gain(name: str) -> Callable[[Any, str], Translation]:
    def tr(v: Any, est: str) -> Translation:
        return Translation(name, COMPLEMENTARY, refused="it belongs to imu_complementary_filter's own filter (Valenti "
                           "et al.), which no node here runs; the nearest is mahony_node (kp, ki)")
    return tr


_NO_GAIN = {
    "riann": "riann_node has no gain to tune (RIANN is a trained network); madgwick_node runs a Madgwick filter",
    "mahony": "mahony_node's gains are kp and ki (a Mahony filter)",
    "vqf": "vqf_node's time constants are tau_acc and tau_mag",
    "consensus": "consensus_node has no gain to tune (RIANN's network and VQF's tau_acc in consensus)",
    "madgwick": "",
}

#: imu_tools name -> its translation on a node running the given estimator.
ALIASES: dict[str, Callable[[Any, str], Translation]] = {
    "gain": _gain,
    "zeta": _zeta,
    "mag_bias_x": _mag_bias(0),
    "mag_bias_y": _mag_bias(1),
    "mag_bias_z": _mag_bias(2),
    "orientation_stddev": _orientation_stddev,
    "yaw_offset": _radians_to("yaw_offset_deg", "yaw offset about the world z axis"),
    "declination": lambda v, est: _declination(v, est),
    "constant_dt": _constant_dt,
    "publish_debug_topics": _debug_topics,
    "stateless": _fixed_flag("stateless", MADGWICK, False, "false: filtering, as the nodes always do",
                             "there is no stateless mode (an orientation from each sample alone): every node is a "
                             "filter"),
    "use_magnetic_field_msg": _fixed_flag("use_magnetic_field_msg", MADGWICK + " (ROS 1)", True,
                                          "true: imu/mag is sensor_msgs/MagneticField, as the nodes always read it",
                                          "imu/mag must be sensor_msgs/MagneticField; geometry_msgs/Vector3Stamped "
                                          "is not read"),
    "do_bias_estimation": _bias_estimation,
    "gain_acc": _complementary_gain("gain_acc"),
    "gain_mag": _complementary_gain("gain_mag"),
    "bias_alpha": _complementary_gain("bias_alpha"),
    "do_adaptive_gain": _complementary_gain("do_adaptive_gain"),
}
#: imu_tools names that are ours too, with the same meaning (nothing to translate).
SAME_NAMES = ("use_mag", "world_frame", "fixed_frame", "publish_tf", "reverse_tf", "remove_gravity_vector")
QOS_OVERRIDES = "qos_overrides."


def translate(name: str, value: Any, estimator: str) -> Translation | None:
    """``name`` (an imu_tools parameter) with ``value`` on a node running ``estimator``; None when ``name`` is not
    an imu_tools name. A value that is not of the imu_tools type is refused with the reason."""
    if name.startswith(QOS_OVERRIDES):
        return Translation(name, "rclcpp", refused="QoS overrides are not read by these nodes: input_qos, "
                           "input_depth and output_depth set the QoS")
    handler = ALIASES.get(name)
    if handler is None:
        return None
    try:
        return handler(value, estimator)
    except ValueError as e:
        return Translation(name, BOTH, refused=str(e))


def unknown_text(name: str, known: Iterable[str], owners: dict[str, list[str]]) -> str:
    """The warning for a parameter the node does not know: whose it is (``owners``: name -> nodes that have it),
    else the closest known name (ours or an imu_tools name the node accepts)."""
    if name in owners:
        return f"'{name}' is a parameter of {' and '.join(owners[name])}, not of this node: ignored"
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.0)
    hint = f" (closest known name: '{close[0]}')" if close else ""
    return f"unknown parameter '{name}' ignored{hint}"
