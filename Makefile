# riann_ros without a system ROS: everything lives in .venv at the repository root.
# `make demo` — set up and evaluate all estimators on the bundled example bags (a real BROAD trial, three synthetic).
# `make test` — set up, lint and run the test suite.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# DDS traffic stays on this machine, in a domain of its own (see README "Quick start"): ROS_DOMAIN_ID, 42 unless you
# set one. The tests follow a ROS_DOMAIN_ID you set, each pytest-xdist worker in a domain of its own (ROS_DOMAIN_ID +
# the worker's number: 42 and 43 with JOBS=2 for ROS_DOMAIN_ID=42); without one every test run picks its own from
# 100 up, so that concurrent runs never meet (test/conftest.py). USER_ROS_DOMAIN_ID: yours, before the default.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
USER_ROS_DOMAIN_ID := $(ROS_DOMAIN_ID)
export ROS_DOMAIN_ID ?= 42
export RMW_IMPLEMENTATION ?= rmw_fastrtps_cpp
# test processes in parallel (pytest-xdist; each worker in a DDS domain of its own, test/conftest.py)
JOBS ?= 2

.PHONY: setup demo test test-scale test-fast check lint bench clean

$(BIN)/.installed: requirements.txt requirements-dev.txt requirements-cluster.txt setup.py package.xml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r requirements-dev.txt
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $@

setup: $(BIN)/.installed

# every estimator (RIANN, the RIANN–VQF consensus, VQF, Madgwick, Mahony) on the bags as recorded and under two
# perturbations a robot meets (stamps of a polled driver, a turn-on gyro bias),
# 6D (the synthetic bags have no magnetometer), roll/pitch plotted for the real trial; DEMO_OUT: another folder
# (test/test_demo_smoke.py runs the demo into one of its own)
DEMO_OUT ?= demo_out
DEMO_TRIAL := 21_undisturbed_fast_combined
demo: $(BIN)/.installed
	rm -rf $(DEMO_OUT)
	$(BIN)/riann-bag-eval bags/*.mcap -e riann,consensus,vqf,madgwick,mahony -s as-recorded -p none -p jitter:10/20/30ms \
		-p bias:3,3,0 --use-mag false \
		--plot-sequence $(DEMO_TRIAL) --jobs 2 --out $(DEMO_OUT)

# ruff (style, imports, complexity ≤ 10) on the whole tree, mypy on the package, vulture (dead code: the package
# and bench/, the tests and launch files counting as users; framework-only names in vulture_whitelist.py; pyproject [tool.vulture])
lint: $(BIN)/.installed
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/vulture

# the whole suite: real DDS, BROAD accuracy, colcon (the README's second command)
test: $(BIN)/.installed lint
	ROS_DOMAIN_ID=$(USER_ROS_DOMAIN_ID) $(BIN)/python -m pytest -m "not scale" -n $(JOBS)

# the corpus-sized runs (marker scale: 1000 listed inputs on a local Dask cluster), minutes on 2 cores
test-scale: $(BIN)/.installed
	ROS_DOMAIN_ID=$(USER_ROS_DOMAIN_ID) $(BIN)/python -m pytest -m scale -n $(JOBS)

# the tests that need no DDS and are not marked slow (50 s on 2 cores with lint, warm): while you work
test-fast: $(BIN)/.installed
	ROS_DOMAIN_ID=$(USER_ROS_DOMAIN_ID) $(BIN)/python -m pytest -m "not ros and not slow" -q -n $(JOBS)

check: lint test-fast

# every benchmark in bench/, short form (bench/run_all.py --full for the BENCHMARKS.md durations)
bench: $(BIN)/.installed
	$(BIN)/python bench/run_all.py

clean:
	rm -rf $(VENV) build install log demo_out .pytest_cache .ruff_cache
