# riann_ros without a system ROS: everything lives in .venv at the repository root.
# `make demo` — set up and evaluate all estimators on the bundled example bags.
# `make test` — set up, lint and run the test suite.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# DDS traffic stays on this machine, in a domain of its own (see README "DDS isolation").
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID ?= 42
export RMW_IMPLEMENTATION ?= rmw_fastrtps_cpp

.PHONY: setup demo test lint bench clean

$(BIN)/.installed: requirements.txt requirements-dev.txt setup.py package.xml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r requirements-dev.txt
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $@

setup: $(BIN)/.installed

demo: $(BIN)/.installed
	rm -rf demo_out
	$(BIN)/riann-bag-eval bags/*.mcap --scenarios realistic --out demo_out

lint: $(BIN)/.installed
	$(BIN)/ruff check .

test: $(BIN)/.installed lint
	$(BIN)/python -m pytest

bench: $(BIN)/.installed
	$(BIN)/python bench/run_all.py

clean:
	rm -rf $(VENV) build install log demo_out .pytest_cache .ruff_cache
