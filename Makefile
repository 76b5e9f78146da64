# Two entry points that set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.lidarkit-installed

.PHONY: demo test test-quick setup system-deps clean

demo: setup
	$(VENV)/bin/lidarkit demo

test: setup
	$(PY) -m pytest -q

test-quick: setup
	$(PY) -m pytest -q -m "not slow"

setup: system-deps $(STAMP)

system-deps:
	@sh scripts/ensure_system_deps.sh

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 10) else "lidarkit needs Python >= 3.10, found " + sys.version.split()[0])'
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	@# opencv-python(-headless) and opencv-contrib-python-headless install the same cv2 package: keep only contrib
	@$(PY) -m pip uninstall -q -y opencv-python-headless opencv-python 2>/dev/null || true
	$(PY) -m pip install -q -e ".[test,ros,gicp,ground]" || $(PY) -m pip install -q -e ".[test,ros]"
	@touch $(STAMP)

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
