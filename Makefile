# xy-twin: every target creates .venv on first use and installs with constraints.txt.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
export RERUN_ANALYTICS=0
export RERUN_DISABLE_ANALYTICS=1
export MPLBACKEND=Agg
export NUMBA_CACHE_DIR ?= $(CURDIR)/.cache/numba
# One BLAS/OpenMP thread per process: the suite runs two workers on two cores, and the
# tuning and identification jobs run their own worker processes (see twin/__init__.py).
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1

.PHONY: demo test test-linuxcnc test-screenshot lint bench clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q -c constraints.txt torch==2.13.0
	$(BIN)/pip install -q -c constraints.txt -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/twin demo

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports

test: lint
	$(BIN)/python -m pytest -n 2 --dist loadfile --durations=15

# LinuxCNC's own interpreter (rs274, Debian's linuxcnc-uspace) as the reference reader.
test-linuxcnc: $(STAMP)
	command -v rs274 >/dev/null || { apt-get update -q && \
	  apt-get install -y -q --no-install-recommends linuxcnc-uspace; }
	$(BIN)/python -m pytest -s tests/controller/test_linuxcnc.py

# The viewer as an engineer sees it: headless Chromium (Debian's chromium) and Playwright
# shoot a run's recording in rerun's web viewer (tools/viewer_screenshot.py).
test-screenshot: $(STAMP)
	command -v chromium >/dev/null || { apt-get update -q && \
	  apt-get install -y -q --no-install-recommends chromium; }
	$(BIN)/pip install -q -c constraints.txt -e '.[screenshot]'
	XY_TWIN_SCREENSHOT=1 $(BIN)/python -m pytest -s tests/telemetry/test_screenshot.py

bench: $(STAMP)
	$(BIN)/pip install -q -c constraints.txt -e '.[dev,bench]'
	@for b in bench/*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .cache .pytest_cache build *.egg-info
