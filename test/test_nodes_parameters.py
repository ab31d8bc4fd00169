"""Parameters as users write them (riann_ros.nodes.parameters), on the real node executables over DDS.

* every parameter of every node takes what YAML, the command line or a launch file make of a natural spelling
  (``use_mag: false`` a bool, ``nominal_rate: 200`` an integer, ``ensemble: 4.0`` a double, ``"true"`` a string,
  ``[0, 0, 1.5e-6]`` a mixed list), at start-up and at run time;
* unknown names are warned about with the closest known name; imu_tools' names are translated or refused;
* imu_filter_madgwick's own 9D parameter file (test/fixtures/imu_filter_madgwick_9d.yaml) starts madgwick_node
  and riann_node with the same meaning: their outputs equal the offline core with the translated parameters;
* an integer where a float is declared works (start-up, run time), a string is refused with a clear reason, and a
  start-up value out of range ends the node with a clear error.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from rcl_interfaces.msg import Parameter as ParamMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from sensor_msgs.msg import Imu, MagneticField
from test_nodes_node_base import mag_msg, motion

from conftest import ROOT, wait_for, wait_matched
from helpers_ros import imu_msg, publish_paced, quats, stamp_ns
from riann_ros import frames
from riann_ros.estimators import create, estimator_class
from riann_ros.magcal.input import MagConfig, pair_fields
from riann_ros.nodes.outputs import gravity_in_sensor, yaw_rotated
from riann_ros.nodes.parameters import NODE_PARAMS
from riann_ros.ros.services import call_service
from riann_ros.stream import EstimatorStream, GateConfig

pytestmark = pytest.mark.ros

FIXTURE = ROOT / "test" / "fixtures" / "imu_filter_madgwick_9d.yaml"
NODES = ("riann", "madgwick", "mahony", "vqf")
TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
         float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING,
         tuple: ParameterType.PARAMETER_DOUBLE_ARRAY}


def call(client, request, timeout: float = 10.0):
    """A service call, resent every 2 s (Fast DDS may lose the first answer right after discovery)."""
    futures = [client.call_async(request)]
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for f in futures:
            if f.done():
                return f.result()
        if time.monotonic() > end - timeout + 2.0 * len(futures):
            futures.append(client.call_async(request))
        time.sleep(0.005)
    raise AssertionError("no answer from the service")


def client(ros, srv, node: str, what: str):
    c = ros.node.create_client(srv, f"{node}/{what}")
    assert c.wait_for_service(timeout_sec=30), f"{node}/{what}"
    return c


def get_params(ros, node: str, names: list[str]) -> dict:
    c = client(ros, GetParameters, node, "get_parameters")
    values = call(c, GetParameters.Request(names=names)).values
    ros.node.destroy_client(c)
    out = {}
    for name, v in zip(names, values, strict=True):
        out[name] = (v.type, {ParameterType.PARAMETER_BOOL: v.bool_value, ParameterType.PARAMETER_INTEGER:
                              v.integer_value, ParameterType.PARAMETER_DOUBLE: v.double_value,
                              ParameterType.PARAMETER_STRING: v.string_value,
                              ParameterType.PARAMETER_DOUBLE_ARRAY: tuple(v.double_array_value)}.get(v.type))
    return out


def set_param(ros, node: str, name: str, value) -> tuple[bool, str]:
    v = ParameterValue()
    if isinstance(value, bool):
        v.type, v.bool_value = ParameterType.PARAMETER_BOOL, value
    elif isinstance(value, str):
        v.type, v.string_value = ParameterType.PARAMETER_STRING, value
    elif isinstance(value, int):
        v.type, v.integer_value = ParameterType.PARAMETER_INTEGER, value
    elif isinstance(value, tuple):
        v.type, v.double_array_value = ParameterType.PARAMETER_DOUBLE_ARRAY, [float(x) for x in value]
    else:
        v.type, v.double_value = ParameterType.PARAMETER_DOUBLE, value
    c = client(ros, SetParameters, node, "set_parameters")
    r = call(c, SetParameters.Request(parameters=[ParamMsg(name=name, value=v)])).results[0]
    ros.node.destroy_client(c)
    return r.successful, r.reason


def started(node) -> str:
    wait_for(lambda: "parameters:" in node.output() or node.proc.poll() is not None, 60, "the start-up line")
    assert node.proc.poll() is None, f"the node exited: {node.output()}"
    time.sleep(0.3)  # the warnings after the start-up line
    return node.output()


# -- use_mag and every other parameter in the types users write --------------------------------------------------
@pytest.mark.parametrize("how, value, expected", [
    ("cli", "false", "false"), ("cli", "true", "true"), ("cli", "auto", "auto"), ("cli", "False", "false"),
    ("yaml", "false", "false"), ("yaml", "'true'", "true"), ("yaml", "True", "true"),
])
def test_use_mag_takes_its_documented_values(ros, start_node, tmp_path, how, value, expected):
    """use_mag is a string parameter (auto, true, false), and false or True given as a bool (what YAML and the
    command line make of them) is taken as that string: the node starts and subscribes imu/mag unless false."""
    ns = f"/use_mag_{how}_{value.strip(chr(39)).lower()}"
    if how == "cli":
        args = ("-p", f"use_mag:={value}")
    else:
        f = tmp_path / "p.yaml"
        f.write_text(f"/**:\n  ros__parameters:\n    use_mag: {value}\n")
        args = ("--params-file", str(f))
    node = start_node("madgwick_node", "-r", f"__ns:={ns}", *args)
    log = started(node)
    assert f"use_mag={expected}" in log
    assert get_params(ros, f"{ns}/madgwick_node", ["use_mag"])["use_mag"] == (ParameterType.PARAMETER_STRING,
                                                                              expected)
    pub = ros.publisher(MagneticField, f"{ns}/imu/mag")  # subscribed unless use_mag is false
    if expected == "false":
        time.sleep(2.0)
        assert pub.get_subscription_count() == 0
    else:
        wait_for(lambda: pub.get_subscription_count() == 1, 20, "the node's imu/mag subscription")
    ros.destroy(pub)


def natural(spec):
    """A value for ``spec`` spelled as YAML or a launch file types it otherwise than the spec (None: nothing to try)."""
    d = spec.default
    if isinstance(d, bool):
        return "True" if d else "off"  # strings (a launch substitution, a quoted YAML value)
    if isinstance(d, str):
        if spec.name == "use_mag":
            return False
        return d.upper() if spec.choices else (7 if spec.name == "fixed_frame" else None)
    if isinstance(d, tuple):
        return [int(v) for v in d] if all(float(v).is_integer() for v in d) else None
    if isinstance(d, int):
        return float(d)  # ensemble: 4.0
    if float(d).is_integer():
        return int(d)  # nominal_rate: 100
    for v in (math.ceil(spec.min), 1, 0):
        if spec.min <= v <= spec.max:
            return v
    return str(d)  # mag_timeout: "0.5"


def test_every_parameter_of_every_node_takes_what_users_write(ros, start_node, tmp_path):
    """Each node gets a parameter file with every one of its parameters spelled in another type than its own
    (plus a list mixing integers and floats, which rcl's parser refuses); all start, and each parameter holds the
    converted value in its own type. At run time an integer for a float and a string for a bool are taken too."""
    nodes, expected = {}, {}
    for name in NODES:
        specs = [*NODE_PARAMS, *estimator_class(name).PARAMS]
        values = {s.name: natural(s) for s in specs if natural(s) is not None}
        values["mag_hard_iron"] = [0, 0, 1.5e-6]
        f = tmp_path / f"{name}.yaml"
        f.write_text(yaml.safe_dump({"/**": {"ros__parameters": values}}))
        nodes[name] = start_node(f"{name}_node", "-r", f"__ns:=/every_{name}", "--params-file", str(f))
        specs_by_name = {s.name: s for s in specs}
        expected[name] = {k: specs_by_name[k].coerce(v) for k, v in values.items()}
        expected[name]["mag_hard_iron"] = (0.0, 0.0, 1.5e-6)
    for name, node in nodes.items():
        started(node)
        got = get_params(ros, f"/every_{name}/{name}_node", sorted(expected[name]))
        for k, want in expected[name].items():
            assert got[k][0] == TYPES[type(want)], (name, k, got[k])
            assert got[k][1] == pytest.approx(want) if isinstance(want, float | tuple) else got[k][1] == want, (
                name, k, got[k], want)
    assert expected["riann"]["ensemble"] == 4 and expected["madgwick"]["use_mag"] == "false"
    assert expected["vqf"]["world_frame"] == "enu" and expected["riann"]["nominal_rate"] == 100.0
    # run time: an integer for a float, a string for a bool, a bool-like string, all in the parameter's type
    assert set_param(ros, "/every_madgwick/madgwick_node", "beta", 1) == (True, "")
    assert set_param(ros, "/every_vqf/vqf_node", "rest_bias_est", "false") == (True, "")
    assert set_param(ros, "/every_riann/riann_node", "yaw_offset_deg", "90") == (True, "")
    assert get_params(ros, "/every_madgwick/madgwick_node", ["beta"])["beta"] == (ParameterType.PARAMETER_DOUBLE, 1.0)
    assert get_params(ros, "/every_vqf/vqf_node", ["rest_bias_est"])["rest_bias_est"] == (
        ParameterType.PARAMETER_BOOL, False)
    ok, reason = set_param(ros, "/every_madgwick/madgwick_node", "beta", "fast")
    assert not ok and "DOUBLE" in reason, reason
    assert not set_param(ros, "/every_vqf/vqf_node", "rest_bias_est", "maybe")[0]


# -- unknown names, imu_tools' names ------------------------------------------------------------------------
def synthetic(n: int, rate: float = 200.0):
    rng = np.random.default_rng(5)
    stamps = 1_000_000_000 + (np.arange(n) * 1e9 / rate).astype(np.int64)
    return stamps, np.array([0.5, -0.3, 9.7]) + rng.normal(0, 0.3, (n, 3)), rng.normal(0, 0.3, (n, 3))


def test_gain_sets_beta_and_unknown_names_are_named(ros, start_node):
    """madgwick_node -p gain:=0.1: gain is imu_filter_madgwick's name of beta (the output equals the core with
    beta = beta_marg = 0.1); a typo, another node's parameter or a name imu_tools means otherwise each get a warning
    naming what to write instead."""
    node = start_node("madgwick_node", "-p", "input_qos:=reliable", "-p", "nominal_rate:=200", "-p", "gain:=0.1",
                      "-p", "gian:=1.0", "-p", "kp:=2.0", "-p", "bta:=0.3", "-p", "zeta:=0.02",
                      "-p", "mag_hard_iron:=[0, 0, 1.5e-6]")
    log = started(node)
    assert "parameter 'gain' (imu_filter_madgwick) = 0.1: beta = 0.1, beta_marg = 0.1" in log
    assert "unknown parameter 'gian' ignored (closest known name: 'gain')" in log
    assert "unknown parameter 'bta' ignored (closest known name: 'beta')" in log
    assert "'kp' is a parameter of mahony_node, not of this node: ignored" in log
    assert "parameter 'zeta' (imu_filter_madgwick) = 0.02 refused: our Madgwick filter has no zeta" in log
    assert "mag_hard_iron: a list mixing integers and floats, read as floats" in log
    got = get_params(ros, "/madgwick_node", ["beta", "beta_marg", "mag_hard_iron"])
    assert got["beta"][1] == got["beta_marg"][1] == 0.1 and got["mag_hard_iron"][1] == (0.0, 0.0, 1.5e-6)
    pub = ros.publisher(Imu, "imu/data_raw")
    att = ros.collect(QuaternionStamped, "imu/madgwick/attitude")
    wait_matched([pub], [att], "madgwick_node")
    stamps, acc, gyr = synthetic(300)
    publish_paced(pub, [imu_msg(s, a, g) for s, a, g in zip(stamps, acc, gyr, strict=True)], att.messages, 300)
    q, ok = EstimatorStream(create("madgwick", beta=0.1, beta_marg=0.1), GateConfig(nominal_rate=200.0)).process_batch(
        stamps, acc, gyr)
    q_default, _ = EstimatorStream(create("madgwick"), GateConfig(nominal_rate=200.0)).process_batch(stamps, acc, gyr)
    assert len(att.messages) == 300 and ok.all()
    assert np.abs(quats(att.messages) - q).max() < 1e-6
    assert np.abs(q - q_default).max() > 1e-3  # beta 0.1 is not the default: the test would see a silent gain
    ros.destroy(pub, att)


def test_our_name_wins_over_an_imu_tools_name(ros, start_node):
    node = start_node("madgwick_node", "-p", "gain:=0.2", "-p", "beta_marg:=0.05", "-p", "mag_bias_z:=2e-6")
    log = started(node)
    assert "parameter 'gain' (imu_filter_madgwick) ignored: beta_marg set too" in log
    got = get_params(ros, "/madgwick_node", ["beta", "beta_marg", "mag_hard_iron"])
    assert (got["beta"][1], got["beta_marg"][1]) == (0.033, 0.05)  # gain applied to neither
    assert got["mag_hard_iron"][1] == (0.0, 0.0, 2e-6)


def test_a_parameter_file_for_another_node_name_is_reported(ros, start_node):
    """imu_tools' files are keyed by its node name (imu_filter): rcl skips such a section for madgwick_node in
    silence; the node names the section, its parameters and how to apply them."""
    node = start_node("madgwick_node", "--params-file", str(FIXTURE))
    log = started(node)
    assert f"parameter file {FIXTURE}: section 'imu_filter' does not apply to this node (/madgwick_node)" in log
    assert "gain, mag_bias_x" in log and "--ros-args -r __node:=imu_filter" in log
    assert "beta=0.033" in log


# -- imu_filter_madgwick's own 9D file ---------------------------------------------------------------------
RATE = 400.0
IMU_TOOLS = yaml.safe_load(FIXTURE.read_text())["imu_filter"]["ros__parameters"]


def expected_9d(name: str, stamps, acc, gyr, mag, sent):
    """The node's output as the offline core gives it with the file's values in our parameters and units."""
    p = IMU_TOOLS
    mag_cfg = MagConfig(use_mag="true", mag_hard_iron=(p["mag_bias_x"], p["mag_bias_y"], p["mag_bias_z"]),
                        declination_deg=math.degrees(p["declination"]))
    est = create("madgwick", beta=p["gain"], beta_marg=p["gain"]) if name == "madgwick" else create(name)
    fields = pair_fields(stamps, stamps[sent], mag[sent], mag_cfg.timeout_ns)
    q_enu, ok = EstimatorStream(est, GateConfig(nominal_rate=RATE), mag_cfg).process_batch(stamps, acc, gyr, fields)
    assert ok.all()
    q_world = np.array([yaw_rotated(frames.to_world_scalar(*q, p["world_frame"]), p["yaw_offset"]) for q in q_enu])
    return q_enu, q_world


@pytest.mark.parametrize("name", ["madgwick", "riann"])
def test_imu_filter_madgwick_9d_file_starts_the_node_with_the_same_meaning(ros, start_node, name):
    """The node runs under imu_tools' node name (as in a launch file that swaps imu_filter_madgwick for it) with
    imu_filter_madgwick's own 9D parameter file: each name is taken with its meaning (gain = Madgwick's beta,
    mag_bias_* = hard iron in tesla, declination and yaw_offset in radians, orientation_stddev in radians, gravity
    removed, roll/pitch/yaw published) or refused with the reason (riann_node: gain and zeta). Over DDS, with a
    400 Hz IMU and a 100 Hz magnetometer, the outputs equal the offline core with those values."""
    node = start_node(f"{name}_node", "-r", "__node:=imu_filter", "--params-file", str(FIXTURE),
                      "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}")
    log = started(node)
    att_topic, imu_topic = ("imu/madgwick/attitude", "imu/madgwick/data") if name == "madgwick" else (
        "imu/attitude", "imu/data")
    rpy_topic = att_topic.rsplit("/", 1)[0] + "/rpy"
    # what the log says, name by name
    if name == "madgwick":
        assert "parameter 'gain' (imu_filter_madgwick) = 0.1: beta = 0.1, beta_marg = 0.1" in log
        assert "parameter 'zeta' (imu_filter_madgwick) = 0.0: 0: no gyro drift term" in log
    else:
        assert "parameter 'gain' (imu_filter_madgwick) = 0.1 refused: it is the gain of imu_filter_madgwick's " \
               "Madgwick filter: riann_node has no gain to tune" in log
        assert "parameter 'zeta' (imu_filter_madgwick) = 0.0 refused" in log
    for text in ("'mag_bias_x' (imu_filter_madgwick) = 2e-06: mag_hard_iron[0] = 2e-06",
                 "'declination' (imu_filter_madgwick) = 0.1: declination_deg = 5.72958",
                 "'yaw_offset' (imu_filter_madgwick) = 0.2: yaw_offset_deg = 11.4592",
                 "'orientation_stddev' (imu_tools) = 0.05: roll_pitch_stddev_deg = 2.86479, mag_yaw_stddev_deg",
                 "'publish_debug_topics' (imu_tools) = True: publish_rpy = True",
                 "'constant_dt' (imu_tools) = 0.0: 0: dt from the header stamps",
                 "'stateless' (imu_filter_madgwick) = False: false: filtering",
                 "publish_tf: tf2_msgs not available", "use_mag=true", "remove_gravity_vector=True",
                 "reverse_tf=False", "fixed_frame=odom", "world_frame=enu"):
        assert text in log, text
    assert "unknown parameter" not in log
    # over DDS
    pub_imu = ros.publisher(Imu, "imu/data_raw")
    pub_mag = ros.publisher(MagneticField, "imu/mag")
    att = ros.collect(QuaternionStamped, att_topic)
    imu_out = ros.collect(Imu, imu_topic)
    rpy = ros.collect(Vector3Stamped, rpy_topic)
    wait_matched([pub_imu, pub_mag], [att, imu_out, rpy], f"{name}_node (log: {node.output()})")
    n = int(4 * RATE)
    stamps, acc, gyr, field = motion(n, seed=3)
    raw = field + np.array([IMU_TOOLS[f"mag_bias_{a}"] for a in "xyz"])  # the sensor's hard iron
    sent = []
    for i in range(n):
        j = i + 2
        if j < n and j % 4 == 0:
            pub_mag.publish(mag_msg(stamps[j], raw[j]))
            sent.append(j)
        while i - min(len(att.messages), len(imu_out.messages), len(rpy.messages)) >= 50:
            time.sleep(0.0002)
        pub_imu.publish(imu_msg(stamps[i], acc[i], gyr[i]))
        time.sleep(0.0005)
    wait_for(lambda: min(len(att.messages), len(imu_out.messages), len(rpy.messages)) >= n, 60,
             f"outputs ({len(att.messages)} of {n}; log: {node.output()[-2000:]})")
    time.sleep(0.3)
    assert [stamp_ns(m) for m in att.messages] == stamps.tolist()
    q_enu, q_world = expected_9d(name, stamps, acc, gyr, raw, sent)
    q_node = quats(att.messages)
    d = np.minimum(np.abs(q_node - q_world).max(axis=1), np.abs(q_node + q_world).max(axis=1))
    assert d.max() < 1e-4, d.max()
    # imu/data: covariance from orientation_stddev (radians), gravity removed, orientation = imu/attitude
    var = IMU_TOOLS["orientation_stddev"] ** 2
    cov = np.array([m.orientation_covariance for m in imu_out.messages])
    np.testing.assert_allclose(cov[:, [0, 4]], var, rtol=1e-9)
    yaw = cov[:, 8]  # 9D: from orientation_stddev as well; 6D (before the field is used): unobservable
    assert (np.isclose(yaw, var) | np.isclose(yaw, math.radians(180.0) ** 2)).all() and np.isclose(yaw[-1], var)
    lin = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                    for m in imu_out.messages])
    np.testing.assert_allclose(lin, acc - np.array([gravity_in_sensor(tuple(q)) for q in q_enu]), atol=5e-3)
    tail = slice(n // 2, n)
    assert np.abs(lin[tail]).mean() < 0.3 < np.abs(acc[tail]).mean()  # the motion is a pure rotation: noise left
    rpy_deg = np.array([[m.vector.x, m.vector.y, m.vector.z] for m in rpy.messages])
    want = frames.rpy_deg(q_world)
    wrap = (rpy_deg - want + 180.0) % 360.0 - 180.0
    assert np.abs(wrap).max() < 0.01
    ros.destroy(pub_imu, pub_mag, att, imu_out, rpy)


# -- numbers in either type, start-up values out of range --------------------------------------------------
def _param_client(ros, srv_type, node_name: str, what: str):
    client = ros.node.create_client(srv_type, f"/{node_name}/{what}")
    assert client.wait_for_service(timeout_sec=15)
    return client


def _call(client, req):
    res = call_service(client, req, 10)
    assert res is not None, "no answer from the parameter service"
    return res


def _set(client, name: str, value) -> tuple[bool, str]:
    v = ParameterValue()
    if isinstance(value, str):
        v.type, v.string_value = ParameterType.PARAMETER_STRING, value
    elif isinstance(value, int):
        v.type, v.integer_value = ParameterType.PARAMETER_INTEGER, value
    else:
        v.type, v.double_value = ParameterType.PARAMETER_DOUBLE, value
    req = SetParameters.Request()
    req.parameters = [ParamMsg(name=name, value=v)]
    r = _call(client, req).results[0]
    return r.successful, r.reason


def _get(client, name: str):
    req = GetParameters.Request()
    req.names = [name]
    v = _call(client, req).values[0]
    return {ParameterType.PARAMETER_DOUBLE: ("double", v.double_value),
            ParameterType.PARAMETER_INTEGER: ("integer", v.integer_value)}.get(v.type, (v.type, None))


@pytest.mark.ros
def test_integer_values_for_float_parameters(ros, start_node, tmp_path):
    """-p nominal_rate:=200 and `diagnostics_period: 2` in a params file start the node (stored as doubles);
    a run-time int works, a string is refused with a clear reason, the ranges still hold."""
    params = tmp_path / "ints.yaml"
    params.write_text("/**:\n  ros__parameters:\n    diagnostics_period: 2\n    beta: 0\n")
    node = start_node("madgwick_node", "--params-file", str(params), "-p", "nominal_rate:=200", "-p", "max_dt:=1")
    get = _param_client(ros, GetParameters, "madgwick_node", "get_parameters")
    set_ = _param_client(ros, SetParameters, "madgwick_node", "set_parameters")
    wait_for(lambda: "parameters:" in node.output(), 10, "the start-up log")
    log = node.output()
    assert "nominal_rate=200.0" in log and "diagnostics_period=2.0" in log and "beta=0.0" in log, log
    assert _get(get, "nominal_rate") == ("double", 200.0)
    assert _get(get, "diagnostics_period") == ("double", 2.0)
    assert _set(set_, "nominal_rate", 150) == (True, "")
    assert _get(get, "nominal_rate") == ("double", 150.0)
    assert _set(set_, "beta", 1)[0] and _get(get, "beta") == ("double", 1.0)
    ok, reason = _set(set_, "nominal_rate", "fast")
    assert not ok and "DOUBLE" in reason and "STRING" in reason, reason
    assert not _set(set_, "nominal_rate", 0)[0]  # below the range, as an int too
    assert not _set(set_, "beta", 11)[0]
    assert not _set(set_, "diagnostics_period", 3)[0]  # start-up only
    assert _get(get, "nominal_rate") == ("double", 150.0)
    for c in (get, set_):
        ros.node.destroy_client(c)


@pytest.mark.ros
@pytest.mark.parametrize("args, error", [
    (("-p", "nominal_rate:=fast"), "nominal_rate must be a number, got 'fast'"),
    (("-p", "nominal_rate:=0"), "nominal_rate=0 is below its minimum 1"),
    (("-p", "world_frame:=ecef"), "world_frame must be one of enu, ned, nwu"),
])
def test_bad_start_up_values_exit_with_a_clear_error(start_node, args, error):
    node = start_node("mahony_node", *args)
    assert node.proc.wait(30) == 1
    assert f"mahony_node: error: {error}" in node.output()
