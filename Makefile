# pmsm_sysid — two-command set-up: `make demo`, `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
CLI := $(VENV)/bin/pmsm-sysid
STAMP := $(VENV)/.installed
DEMO_DIR ?= demo_out
# the lint commands, the same in `lint` and `test`
RUFF := $(VENV)/bin/ruff check pmsm_sysid test bench scripts
MYPY := $(VENV)/bin/mypy pmsm_sysid

# Keep DDS discovery on this host.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID ?= 42
export PIP_DISABLE_PIP_VERSION_CHECK := 1
# One BLAS thread per process: the fits are small and the test workers already use both cores.
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1
# Let Python keep compiled modules (__pycache__, ignored by git): a shell that sets
# PYTHONDONTWRITEBYTECODE would make each of the suite's processes compile the package and
# pytest rewrite every test module again (about 4 s of each test process's start).
unexport PYTHONDONTWRITEBYTECODE

.PHONY: venv demo test check browser lint typecheck bags bench docs colcon clean

venv: $(STAMP)

$(STAMP): requirements.lock setup.py setup.cfg pyproject.toml package.xml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q -r requirements.lock
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	rm -rf pmsm_sysid.egg-info  # a legacy editable install's metadata, replaced by the line above
	touch $(STAMP)

demo: $(STAMP)
	ROS_LOG_DIR=$(abspath $(DEMO_DIR))/ros_log bash scripts/demo.sh $(DEMO_DIR)

lint: $(STAMP)
	$(RUFF)
	$(MYPY)

# the whole suite (what CI runs); the browser test's Chromium is installed first. Three test
# processes on two cores: the live ROS tests spend much of their time waiting on replays and
# discovery, and a third process computes meanwhile (idle, one after the other: three 186.5 s,
# two 193.3 s).
# mypy runs beside pytest (on a fresh clone it checks from scratch: about 12 s of CPU, under
# a second once its cache exists); its output follows the tests'.
# pytest rewrites the asserts of each test module (and of this package's modules: it is a
# pytest plugin) as it imports them, and keeps the result in __pycache__. On a fresh tree
# the three test processes would each rewrite all of them (about 3 s of CPU apiece): one
# collection, beside mypy, does it once first.
test: $(STAMP) browser
	$(RUFF)
	@log=$$(mktemp); echo "$(MYPY) (beside the tests)"; \
	$(MYPY) >$$log 2>&1 & typing=$$!; \
	if [ -z "$$(find test/__pycache__ -name '*-pytest-*.pyc' -print -quit 2>/dev/null)" ]; then \
	  $(PY) -m pytest --collect-only -q -p no:cacheprovider test >/dev/null 2>&1; fi; \
	ROS_LOG_DIR=$$(mktemp -d) $(PY) -m pytest -n 3 --dist loadgroup -q test; tests=$$?; \
	wait $$typing; typed=$$?; echo "$(MYPY):"; cat $$log; rm -f $$log; \
	test $$tests -eq 0 -a $$typed -eq 0

# the edit-test loop: lint + the tests that need no ROS and are not slow (about 58 s on 2 cores)
check: $(STAMP) lint
	$(PY) -m pytest -n 2 --dist loadgroup -q --without-ros -m "not slow" test

# headless Chromium for the report's browser test (Debian package, as root); once
browser:
	@bash scripts/install_browser.sh $(VENV)/.browser

bags: $(STAMP)
	bash scripts/make_bags.sh
	bash scripts/make_concealed_bags.sh

bench: $(STAMP)
	$(PY) bench/ofr_bench.py
	$(PY) bench/gfrf_bench.py
	$(PY) bench/simulate_bench.py

# colcon build of this package as ament_python in a temporary workspace (also part of `test`)
colcon: $(STAMP)
	$(PY) -m pytest -q -p no:cacheprovider test/test_colcon.py

docs: $(STAMP)
	$(PY) scripts/api_docs.py docs/api

clean:
	rm -rf docs/api $(VENV) $(DEMO_DIR) .pytest_cache .mypy_cache .ruff_cache *.egg-info
