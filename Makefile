# The course's two commands: `make lab` opens the course, `make test` runs every test.
# Both create .venv and install everything first (ROS 2 Jazzy from PyPI wheels).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.course-installed
PORT   ?= 8888
WORK   ?= $(HOME)/ros2-course-work
# Parallel test workers, by kind of test. Logic tests (every test not marked 'timing') mostly wait
# for discovery and child processes, and judge nothing by the clock, so JOBS workers keep a 2-core
# machine busy; each worker has its own ROS domain. Tests marked 'timing' measure time (rates,
# latencies, DDS's deadline and lease events) and judge it with the one timing verdict, which measures
# again on a busy machine: they run in a stage of their own with TIMING_JOBS workers, so that they do
# not starve each other (README: how these numbers were measured); a timing test marked 'runs_alone' (it
# loads the machine by design) runs while no other test runs (tests/timing_turns.py).
# `make test JOBS=1` runs one at a time.
# Files are dealt out whole (--dist loadfile: a notebook's cells share one kernel, a test file's
# tests their module fixtures), longest first by the seconds in tests/durations.json
# (conftest.py; --no-loadscope-reorder keeps that order instead of xdist's count of tests).
JOBS   ?= 5
TIMING_JOBS ?= $(if $(filter 1,$(JOBS)),1,2)
XDIST  := -n $(JOBS) --dist loadfile --no-loadscope-reorder
TIMING_XDIST := -n $(TIMING_JOBS) --dist loadfile --no-loadscope-reorder
# The notebooks get 4 workers: their cells make claims that the one timing verdict judges, and the stage's
# own kernels are the load it measures. With 6 (one more than JOBS), a fresh-clone CI run on a slower day
# had chapter 03's throughput check inconclusive after 3 measurements in both passes ("5 other course
# kernels" named) and a chapter 09 cell past the cell timeout (379 s); the same hour, 4 took 314 s and
# passed all 978.
# `JOBS=1` still runs one at a time.
NB_JOBS ?= $(if $(filter 1,$(JOBS)),1,4)
NB_XDIST := -n $(NB_JOBS) --dist loadfile --no-loadscope-reorder
# The slowest honest cell takes about 25 s on a loaded 2-core machine.
# The unit tests; the container image's tests (tests/test_image.py) are `make test-image`'s, and every
# notebook run all in a browser (tests/test_all_notebooks_browser.py) is `make test-browser`'s.
UNIT   := tests --ignore=tests/test_image.py --ignore=tests/test_all_notebooks_browser.py
NBVAL  := --nbval --nbval-current-env --nbval-sanitize-with tests/nbval_sanitize.cfg \
          --nbval-cell-timeout=120 -p no:cacheprovider

.PHONY: setup lab test unit logic timing notebooks soak durations lint bench execute book test-pythons release grade \
        grade-all clean image test-image test-browser
.DEFAULT_GOAL := lab

setup: $(STAMP)
	@$(PY) -m course_helpers.core.build_interfaces

$(STAMP): environment.txt pyproject.toml tools/jupyterlab/overrides.json
	@$(PYTHON) tools/check_platform.py
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r environment.txt
	@# rfc3987-syntax (jsonschema's format-nongpl extra, which jupyter-events asks for) builds about thirty
	@# Earley parsers when jsonschema is imported: 2 s of CPU in every process that imports nbformat (each
	@# test worker, JupyterLab, nbgrader, nbclient). Without it jsonschema skips only its "iri" formats.
	$(PY) -m pip uninstall --quiet --yes rfc3987-syntax
	$(PY) -m pip install --quiet --no-deps --no-build-isolation -e .
	@# JupyterLab settings for the course: no "news" pop-up, no update check
	@mkdir -p $(VENV)/share/jupyter/lab/settings
	@cp tools/jupyterlab/overrides.json $(VENV)/share/jupyter/lab/settings/overrides.json
	@# The classroom server's proxy (npm); without npm the classroom test is skipped with the reason
	@command -v npm >/dev/null 2>&1 && npm install --silent --prefix $(VENV)/node --no-audit --no-fund \
	    configurable-http-proxy@5.3.0 >/dev/null 2>&1 || echo "note: configurable-http-proxy not installed (npm)"
	@touch $(STAMP)

# `make lab` opens your own copy of the notebooks (WORK), brought up to date with the course
# without overwriting your edits (tools/working_copy.py merges cell by cell), at the first
# notebook, without nbgrader's instructor tools; it prints the URL to open, and Ctrl-C stops it
# cleanly (tools/lab.py). `make lab INSTRUCTOR=1` keeps nbgrader (docs/assignments.md).
INSTRUCTOR ?=
lab: setup
	@$(PY) tools/lab.py --work $(WORK) --port $(PORT) $(if $(filter-out 0 no false,$(INSTRUCTOR)),--instructor,)

# -rfEs: every failure, error and skipped test is listed at the end, a skip with its reason (what is
# missing and how to get it).
# The three stages, in this order: the logic tests, the tests marked 'timing', the notebooks.
# PYTEST_EXTRA is added to each stage's pytest (benchmarks/soak.py passes --junitxml).
PYTEST_EXTRA ?=
test: setup
	@$(MAKE) --no-print-directory logic timing notebooks

unit: setup
	@$(MAKE) --no-print-directory logic timing

logic: setup
	$(PY) -m pytest $(UNIT) -m "not timing" -q -rfEs $(XDIST) $(PYTEST_EXTRA)

timing: setup
	$(PY) -m pytest $(UNIT) -m timing -q -rfEs $(TIMING_XDIST) $(PYTEST_EXTRA)

# Every notebook as a student meets it: Run All in JupyterLab and headless Chromium, then every slider
# and button once; no error may reach JupyterLab's log console (tests/test_all_notebooks_browser.py).
# Two workers, each with its own JupyterLab, one notebook at a time each. Not part of `make test`.
test-browser: setup
	$(PY) -m pytest tests/test_all_notebooks_browser.py -q -rfEs -n 2 --dist load

# Strict nbval of every notebook, then each notebook once more in the same kernel (notebooks/conftest.py).
notebooks: setup
	$(PY) -m pytest $(NBVAL) $(NB_XDIST) notebooks -q -rfEs $(PYTEST_EXTRA)

# Measure both stages and record each file's seconds in tests/durations.json (the order above).
durations: setup
	$(PY) -m pytest $(UNIT) -m "not timing" -q -rfEs $(XDIST) --record-durations
	$(PY) -m pytest $(UNIT) -m timing -q -rfEs $(TIMING_XDIST) --record-durations
	$(PY) -m pytest $(NBVAL) $(NB_XDIST) notebooks -q -rfEs --record-durations

lint: setup
	$(VENV)/bin/ruff check course_helpers tests benchmarks tools notebooks book classroom

# The stages N times (RUNS, default 3) beside BUSY CPU-bound processes (default 0): pass counts, every
# failure with its message, each stage's times (benchmarks/soak.py; STAGES picks some).
RUNS ?= 3
BUSY ?= 0
STAGES ?= logic timing notebooks
soak: setup
	$(PY) -m benchmarks.soak --runs $(RUNS) --busy $(BUSY) --stages $(STAGES)

bench: setup
	$(PY) benchmarks/executor_throughput.py
	$(PY) benchmarks/discovery_latency.py
	$(PY) benchmarks/discovery_after_crash.py

# Re-execute the notebooks in place so the committed outputs are fresh (maintainers).
execute: setup
	$(PY) tools/execute_notebooks.py notebooks/*.ipynb

# Graded assignments with nbgrader (docs/assignments.md): the student release of some chapters
# (CHAPTERS=04 or every chapter with exercises), then the grading of a folder of submissions.
CHAPTERS ?=
release: setup
	$(PY) tools/assignments.py release $(CHAPTERS)

grade: setup
	@test -n "$(SUBMISSIONS)" -a -n "$(ASSIGNMENT)" || \
	    { echo "usage: make grade SUBMISSIONS=folder ASSIGNMENT=04_services"; exit 2; }
	$(PY) tools/assignments.py grade $(SUBMISSIONS) --assignment $(ASSIGNMENT)

# Maintainers: every assignment graded end to end with real nbgrader (about 25 minutes, so not part of
# `make test`). Releases CHAPTERS (default: every chapter with a graded exercise) into build/grade-all,
# grades each one's untouched starting code and then its reference, prints the table and each chapter's
# time, and fails naming the chapter and exercise where a reference lost a point or a starting code kept all.
grade-all: setup
	$(PY) -u tools/assignments.py grade-all $(CHAPTERS)

# Set-up and strict nbval from a fresh clone on every Python 3.10-3.13 found (PYTHON310=... or PATH).
test-pythons:
	$(PYTHON) tools/test_pythons.py

# The course's container image (Dockerfile; Codespaces, Binder, Zero to JupyterHub, docker run) with
# Docker or Podman, whichever works here; `make test-image` builds it and tests it as students use it
# (tests/test_image.py), then prints its size and the seconds of each stage. tools/container/.
IMAGE ?= ros2-course
image:
	$(PYTHON) -m tools.container.build_image --tag $(IMAGE)

test-image: setup
	$(PY) -m tools.container.run_image_tests --tag $(IMAGE) --jobs $(NB_JOBS)

# The course website from the committed notebooks (nothing executed, nothing downloaded).
book: setup
	$(PY) tools/build_book.py

clean:
	rm -rf $(VENV) build install log tests/artifacts
