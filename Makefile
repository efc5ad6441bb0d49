# The environment is created from the project's own files whenever it is missing
# or pyproject.toml changed; every target below runs inside it. Bytecode is compiled at install:
# where PYTHONDONTWRITEBYTECODE is set (as on the machines measured here) no process writes it
# later, and each would compile what it imports (--no-compile saved 9 s of install and cost the
# suite about 70 s on 2 cores).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
SHARED ?= ../shared

.PHONY: demo test check timings bench lint clean venv wheelhouse browser screenshots

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,lint]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/omnisort demo --out build/demo

# Every test on every core (pytest-xdist; a module's tests stay on one worker, and so do the
# modules of a shared group in tests/conftest.py, so their fixtures are built once; the groups
# go out longest first by tests/timings.json, so no long one starts last while the other cores
# idle). One worker per core: a third on 2 cores (the cores were 79 % busy with 2) took the
# fresh-clone run from 527 s to 505 s, too little for the load it adds to the real-time
# processes (the virtual cell's controller, the browsers). The 15 slowest tests close the run.
# The type check runs beside the tests, niced: they leave about a fifth of the 2 cores idle
# (real-time waits; 960 s of CPU in a 610 s run), which its 20 s of CPU fills instead of
# running first; the target fails if either does, and prints mypy's report after the tests'.
TEST_WORKERS ?= auto
test: $(STAMP) browser
	$(BIN)/ruff check .
	@mkdir -p build; nice -n 10 $(BIN)/mypy > build/mypy.log 2>&1 & types=$$!; \
	$(BIN)/python -m pytest -q -ra -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder \
	  --durations=15; tests=$$?; \
	wait $$types; typed=$$?; echo "mypy:"; cat build/mypy.log; \
	exit $$(( tests ? tests : typed ))

# The operator interface's browser tests drive Debian's Chromium through its chromedriver
# (tests/ui/ui_procs.py): installed here when missing (as root, or through sudo).
browser:
	@command -v chromium >/dev/null && command -v chromedriver >/dev/null || { \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	  $$SUDO apt-get install -y -qq --no-install-recommends chromium chromium-driver; }

# The edit loop: lint, types and the quick test modules (under 4 s each in tests/timings.json),
# stopping at the first failure.
check: lint
	$(BIN)/python -m pytest -q -x -n auto --dist loadfile --no-loadscope-reorder --quick

# Every test, recording each module's time in tests/timings.json (what `check` selects by).
timings: lint browser
	$(BIN)/python -m pytest -q -ra -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --record-timings tests/timings.json

# The documentation's screenshots (docs/images) renewed by the browser tests, which otherwise
# write them to build/screenshots.
screenshots: lint browser
	OMNISORT_SCREENSHOTS=docs/images $(BIN)/python -m pytest -q -n auto --dist loadfile tests/ui

bench: $(STAMP)
	$(BIN)/python -m benchmarks --shared $(SHARED)

# Every wheel the cell PC needs (this project and its dependencies) for an offline
# `deploy/install.sh --wheelhouse $(WHEELHOUSE)`; needs the network, and a machine with the
# cell PC's Python version and architecture (wheels are built or downloaded for this one).
WHEELHOUSE ?= build/wheelhouse
wheelhouse: $(STAMP)
	rm -rf $(WHEELHOUSE)
	$(BIN)/python -m pip wheel --quiet . -w $(WHEELHOUSE)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

clean:
	rm -rf build .pytest_cache
