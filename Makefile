# Two commands do everything on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test

.PHONY: demo test check lint docs bench sizes clean venv viewer-test-deps catalogue-test-deps report-test-deps

# Everything installed is byte-compiled. It must be: where PYTHONDONTWRITEBYTECODE is set (as in this
# machine's environment) Python never caches what it compiles, and every process would compile pandas, rerun
# and the rest from source again. pip compiles on one core (about 45 s of a 96 s
# install here); compileall does it on every core. A file that does not compile is left as pip leaves it.
# The packages' own test suites (folders named test or tests, a quarter of the files) are never imported:
# left out.
# `make demo` installs what tankdaq needs to run, not the test toolchain; `make test` (and lint, docs,
# bench) adds the `test` extra on top.
# Each long step runs under tankdaq's heartbeat (src/tankdaq/heartbeat.py, standard library only, run from
# the source before tankdaq is installed): a line when it starts, one every 5 s, one when it ends.
HEARTBEAT := PYTHONPATH=src $(PYTHON) -m tankdaq.heartbeat
COMPILE := sh -c '$(BIN)/python -m compileall -q -j 0 -x "/tests?/" $(VENV)/lib >/dev/null || true'
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(HEARTBEAT) "making the environment .venv" $(PYTHON) -m venv $(VENV)
	$(HEARTBEAT) "updating pip" $(BIN)/python -m pip install --quiet --upgrade pip
	$(HEARTBEAT) "installing tankdaq and what it needs to run (the first time: a few minutes)" \
		$(BIN)/python -m pip install --quiet --no-compile -e .
	$(HEARTBEAT) "byte-compiling the installed packages (once)" $(COMPILE)
	touch $(STAMP)

# One install for the tests (the runtime and the test extra in one pass of pip and one byte-compilation):
# on a fresh clone `make test` does not install the runtime first and then walk the venv again.
$(TEST_STAMP): pyproject.toml
	test -x $(BIN)/python || $(HEARTBEAT) "making the environment .venv" $(PYTHON) -m venv $(VENV)
	$(HEARTBEAT) "updating pip" $(BIN)/python -m pip install --quiet --upgrade pip
	$(HEARTBEAT) "installing tankdaq, what it needs and the test toolchain" \
		$(BIN)/python -m pip install --quiet --no-compile -e '.[test]'
	$(HEARTBEAT) "byte-compiling the installed packages" $(COMPILE)
	touch $(STAMP) $(TEST_STAMP)

venv: $(TEST_STAMP)

demo: $(STAMP)
	$(BIN)/python -m tankdaq.prepare
	$(BIN)/tankdaq demo

lint: $(TEST_STAMP)
	$(BIN)/ruff check src tests bench tools
	$(BIN)/ruff format --check src tests bench tools
	$(BIN)/mypy

# The API reference, generated from the docstrings (pdoc) into build/api. Any warning fails the build:
# a module that does not import, a name in __all__ that resolves to nothing. pdoc stops imports from
# running programs; matplotlib runs fc-list once per machine to build its font cache, so on a fresh
# machine the plotting modules would not import under pdoc (PDOC_ALLOW_EXEC lets it).
docs: $(TEST_STAMP)
	PDOC_ALLOW_EXEC=1 $(BIN)/python -W error -m pdoc --docformat restructuredtext -o build/api tankdaq

# The live-view window test runs the real viewer under Xvfb with Mesa's software Vulkan driver
# (Debian packages). Installed where this machine allows (root and apt-get); otherwise say why:
# that test then skips with its reason and the build goes on.
VIEWER_TEST_PACKAGES := xvfb mesa-vulkan-drivers
viewer-test-deps:
	@if command -v Xvfb >/dev/null 2>&1 && ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1; then \
		:; \
	elif [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then \
		echo "make: not root or no apt-get: cannot install $(VIEWER_TEST_PACKAGES); the viewer window test skips"; \
	elif ! (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
			$(VIEWER_TEST_PACKAGES)) >/dev/null 2>&1; then \
		echo "make: apt-get could not install $(VIEWER_TEST_PACKAGES); the viewer window test skips"; \
	fi

# Two pytest workers per core (tools/pytest_workers.py says why and how many): the whole run here took 8:25
# with four workers against 11:04 with two, and all of it passed with six (git history has the runs).
# A test file goes to one worker whole, so a module's fixture is made once (a whole session, killed and
# resumed: 50 s).
TEST_WORKERS := $(shell $(PYTHON) tools/pytest_workers.py)
# --no-loadscope-reorder: xdist would otherwise hand out the files with the most tests first, and the
# docs' examples and the wheel (minutes each, a few tests) would start last (tests/conftest.py orders them).
# Every test phase over 5 s is listed at the end (a test over about half a second is marked slow, `make check`
# leaves it out: tools/mark_slow.py marks them from a run with --durations=0).
# The kernels are built and compiled first, in one process (see src/tankdaq/prepare.py): again here,
# because the source may have changed since the install.
# The run catalogue's PostgreSQL tests start a throwaway server (initdb, pg_ctl) from the Debian
# `postgresql` package, installed where this machine allows; otherwise those tests skip with the reason
# and the SQLite ones still run.
catalogue-test-deps:
	@if ls /usr/lib/postgresql/*/bin/pg_ctl >/dev/null 2>&1; then \
		:; \
	elif [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then \
		echo "make: not root or no apt-get: cannot install postgresql; the PostgreSQL catalogue tests skip"; \
	elif ! (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
			postgresql) >/dev/null 2>&1; then \
		echo "make: apt-get could not install postgresql; the PostgreSQL catalogue tests skip"; \
	fi

# The report's tests open its HTML in a real browser (Debian's chromium, driven by playwright from the
# test extra; the live web view's tests open `--viewer web` in it too) and render its PDF to pages
# (pdftoppm, pdftotext: poppler-utils). Installed where this machine allows; otherwise say why: those tests
# then skip with their reason.
REPORT_TEST_PACKAGES := chromium poppler-utils
report-test-deps:
	@if [ -x /usr/bin/chromium ] && command -v pdftoppm >/dev/null 2>&1 && command -v pdftotext >/dev/null 2>&1; then \
		:; \
	elif [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then \
		echo "make: not root or no apt-get: cannot install $(REPORT_TEST_PACKAGES); the report's browser and PDF tests skip"; \
	elif ! (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
			$(REPORT_TEST_PACKAGES)) >/dev/null 2>&1; then \
		echo "make: apt-get could not install $(REPORT_TEST_PACKAGES); the report's browser and PDF tests skip"; \
	fi

# The kernels are built first (the tests need them; the API docs import the package, so they start after).
# The lint and the type check start beside them, the API docs after them, at the lowest priority (nice 19),
# and go on while the tests run: they take what the tests leave idle (a test waiting on a real-time device
# or server) and do not slow one that waits. Their output is shown at the end; any failing fails the target.
# compileall: pip does not byte-compile an editable install's own source, and with PYTHONDONTWRITEBYTECODE
# set every tankdaq process a test starts would compile the package from source again. The test modules
# are collected once beside the kernels' build, which caches them rewritten for their asserts
# (tests/conftest.py): each worker then collects in about 5 s of CPU, not 10.
CHECKS_LOG := build/checks.log
DOCS_LOG := build/docs.log
test: $(TEST_STAMP) viewer-test-deps catalogue-test-deps report-test-deps
	mkdir -p build
	$(BIN)/python -m compileall -q src
	nice -n 19 $(MAKE) --no-print-directory lint >$(CHECKS_LOG) 2>&1 & checks=$$!; \
	$(BIN)/python -m pytest --collect-only -q -p no:cacheprovider >/dev/null 2>&1 & collected=$$!; \
	$(BIN)/python -m tankdaq.prepare --jit || { wait $$checks; cat $(CHECKS_LOG); exit 1; }; \
	wait $$collected; \
	nice -n 19 $(MAKE) --no-print-directory docs >$(DOCS_LOG) 2>&1 & docs=$$!; \
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=0 --durations-min=5; tested=$$?; \
	wait $$checks; checked=$$?; wait $$docs; documented=$$?; \
	echo "--- lint and types (make lint) ---"; cat $(CHECKS_LOG); \
	echo "--- API docs (make docs) ---"; cat $(DOCS_LOG); \
	test $$checked = 0 || echo "make: the lint or the type check failed (above)"; \
	test $$documented = 0 || echo "make: the API docs failed (above)"; \
	test $$tested = 0 && test $$checked = 0 && test $$documented = 0

# The maintainers' quick loop (README, "Tests"): lint, types, then the tests not marked slow (a test over
# about half a second is marked slow: `make test` runs them) on every core, each module's tests on one worker.
# compileall: with PYTHONDONTWRITEBYTECODE set, each worker would compile the edited source again.
check: lint
	$(BIN)/python -m compileall -q src
	$(BIN)/python -m tankdaq.prepare --jit
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -n auto --dist loadfile --no-loadscope-reorder -m "not slow" -q

bench: $(TEST_STAMP)
	$(BIN)/python bench/run_all.py

# The modules and functions past the size guideline (about 500 lines a module, 80 a function body): a
# report to read, never a failure (tools/sizes.py).
sizes:
	$(PYTHON) tools/sizes.py

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
