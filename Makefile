# Two commands do everything on a fresh Debian machine (Python 3.11+, no GPU):
#   make demo   set up .venv and the system libraries, then run the demo
#   make test   the same set-up, then the wheel check (scripts/check_wheel.sh) and the test suite
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SYSLIBS := libegl1 libopengl0 libgl1-mesa-dri libgomp1
export MUJOCO_GL ?= egl
# test processes (pytest-xdist): one per core
TEST_WORKERS ?= auto

.PHONY: demo test setup syslibs perf profiles clean wheel-check fuzz

setup: syslibs $(STAMP)

# Debian packages for offscreen EGL rendering (MuJoCo) and OpenMP (proxsuite); installed only when missing.
syslibs:
	@missing=""; for p in $(SYSLIBS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  SUDO=""; [ "$$(id -u)" -eq 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $$missing; \
	fi

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c constraints.txt -e '.[test]'
	touch $(STAMP)

demo: setup
	$(VENV)/bin/bigcbf demo

# the wheel check first (its failure does not stop the tests; either failing fails the target), the test
# summary last
test: setup
	@status=0; PY=$(PY) scripts/check_wheel.sh || status=1; \
	$(PY) -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) || status=$$?; exit $$status

# build the wheel, install it into a fresh venv outside the checkout, run the tour's first commands from there
wheel-check: setup
	PY=$(PY) scripts/check_wheel.sh

perf: setup
	$(VENV)/bin/bigcbf perf

# The stack's uncertainty profiles of the shipped simulated robots, made by the twin (record a calibration drive,
# calibrate it): bigcbf/profiles/stack/x3_sim.toml (run, bench) and x3_hardware.toml (bench --suite hardware).
profiles: setup
	$(VENV)/bin/bigcbf profile simulate --robot-profile x3_sim
	$(VENV)/bin/bigcbf profile simulate --robot-profile x3_hardware --base physical

# Fuzz every user input through the REAL commands (scripts/fuzz_inputs.py, issue 21): FUZZ_N cases, each a subprocess
# with a wall and a memory limit; counts per class and family in FUZZ_OUT/summary.md, reproducers in FUZZ_OUT/repro/
FUZZ_N ?= 1000
FUZZ_SEED ?= 0
FUZZ_JOBS ?= 2
FUZZ_OUT ?= renders/fuzz
fuzz: setup
	$(PY) scripts/fuzz_inputs.py --n $(FUZZ_N) --seed $(FUZZ_SEED) --jobs $(FUZZ_JOBS) --timeout 120 --out $(FUZZ_OUT)

clean:
	rm -rf $(VENV) *.egg-info build
