"""The DDS domains of a test run (test/conftest.py): ROS_DOMAIN_ID when it is set, else one picked per run; each
pytest-xdist worker in a domain of its own derived from the run's base; bad values refused with the reason."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from conftest import DOMAIN_MAX, ROOT, dds_domain


def test_domain_follows_ros_domain_id_one_per_worker():
    assert dds_domain({"ROS_DOMAIN_ID": "7"}, 1, 1) == (7, 7)  # no xdist: the domain itself
    workers = {"ROS_DOMAIN_ID": "7", "PYTEST_XDIST_WORKER_COUNT": "3"}
    assert [dds_domain({**workers, "PYTEST_XDIST_WORKER": f"gw{i}"}, 1, 1)[1] for i in range(3)] == [7, 8, 9]
    # a worker takes the base its controlling process handed on, not the domain the controller moved into
    assert dds_domain({"ROS_DOMAIN_ID": "7", "RIANN_TEST_DOMAIN_BASE": "7", "PYTEST_XDIST_WORKER": "gw1"}, 1, 1) == (
        7, 8)
    assert dds_domain({"ROS_DOMAIN_ID": "0"}, 1, 1) == (0, 0)  # 0, ROS's default, is a value like any other


def test_domain_without_ros_domain_id_is_picked_per_run():
    base, domain = dds_domain({}, 4321, 1)
    assert base == domain and 100 <= base <= 196 and base % 4 == 0
    assert dds_domain({"ROS_DOMAIN_ID": " "}, 4321, 1) == (base, domain)  # empty: not set
    # workers derive theirs from their controlling process's pid (their parent): one run, distinct domains
    got = {dds_domain({"PYTEST_XDIST_WORKER": f"gw{i}"}, 999 + i, 4321)[1] for i in range(4)}
    assert got == {base, base + 1, base + 2, base + 3}


def test_bad_domain_is_refused_with_the_reason():
    with pytest.raises(ValueError, match="not a domain ID"):
        dds_domain({"ROS_DOMAIN_ID": "robot"}, 1, 1)
    with pytest.raises(ValueError, match=f"the tests need domains 232 … 233 .* largest ID is {DOMAIN_MAX}"):
        dds_domain({"ROS_DOMAIN_ID": "232", "PYTEST_XDIST_WORKER_COUNT": "2", "PYTEST_XDIST_WORKER": "gw0"}, 1, 1)


@pytest.mark.skipif(not os.environ.get("RIANN_DOMAIN_PROBE"), reason="run by test_workers_run_in_the_given_domain")
def test_probe_domain():
    """Writes this worker's domain (only inside the run below)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(os.path.join(os.environ["RIANN_DOMAIN_PROBE"], worker), "w") as f:
        f.write(os.environ["ROS_DOMAIN_ID"])


@pytest.mark.slow
@pytest.mark.parametrize("given", ["7", ""])
def test_workers_run_in_the_given_domain(tmp_path, given):
    """A real run with two pytest-xdist workers: with ROS_DOMAIN_ID=7 they run in 7 and 8; without it in two
    neighbouring domains of their own."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "RIANN_TEST_DOMAIN"))}
    env.update(ROS_DOMAIN_ID=given, RIANN_DOMAIN_PROBE=str(tmp_path))
    r = subprocess.run([sys.executable, "-m", "pytest", "test/test_conftest_domain.py", "-k", "probe", "-n", "2",
                        "--dist", "each", "-q", "-p", "no:cacheprovider"], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    domains = {p.name: int(p.read_text()) for p in tmp_path.iterdir()}
    assert sorted(domains) == ["gw0", "gw1"], domains
    if given:
        assert domains == {"gw0": 7, "gw1": 8}
    else:
        assert domains["gw1"] == domains["gw0"] + 1 and 100 <= domains["gw0"] <= 196
