# ads_rca: `make demo` runs the main job on the bundled example, `make test` runs the tests.
# Both create .venv from the pinned requirements when it is missing.
SHELL := /bin/bash
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# Network rule: DDS discovery stays on this machine, on a domain of our own.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID ?= 42
export ROS_LOG_DIR ?= $(CURDIR)/.ros_log
export PYTHONDONTWRITEBYTECODE := 1

EXAMPLE := examples/cut_in_perception
OUT := out

.PHONY: venv demo test lint format bench clean

venv: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt constraints.txt setup.py
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q pip==26.3
	$(BIN)/python -m pip install -q -r requirements.txt -r requirements-dev.txt -c constraints.txt
	$(BIN)/python -m pip install -q --no-deps --no-build-isolation -e .
	@touch $(STAMP)

# The offline verdict (JSON + HTML report), then the same run through the live node graph (separate processes,
# local-only DDS), ending with the live verdict and the MCAP recording's path.
demo: $(STAMP)
	$(BIN)/ads-rca diagnose $(EXAMPLE) --json $(OUT)/diagnose.json --report $(OUT)/report.html
	rm -rf $(OUT)/replay_recording
	$(BIN)/ads-rca replay $(EXAMPLE) --domain-id $(ROS_DOMAIN_ID) \
		--json $(OUT)/replay_verdict.json --record $(OUT)/replay_recording

# The suite waits much of its time (DDS discovery, child processes), so it runs in TEST_WORKERS
# pytest-xdist workers even on 2 cores: each test file on one worker (its module fixtures built
# once), the costliest files first (test/conftest.py orders them), each worker on its own slice
# of ROS domains.
TEST_WORKERS ?= 4
test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder test

lint: $(STAMP)
	$(BIN)/ruff check ads_rca test bench launch_scripts setup.py
	$(BIN)/ruff format --check ads_rca test bench launch_scripts setup.py
	$(BIN)/mypy

format: $(STAMP)
	$(BIN)/ruff format ads_rca test bench launch_scripts setup.py
	$(BIN)/ruff check --fix ads_rca test bench launch_scripts setup.py

bench: $(STAMP)
	$(BIN)/python bench/performance.py

clean:
	rm -rf $(VENV) build install log .ros_log $(OUT) .pytest_cache .mypy_cache .ruff_cache
