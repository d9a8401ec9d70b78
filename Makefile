# The course's two commands: `make lab` opens the course, `make test` runs every test.
# Both create .venv and install everything first (ROS 2 Jazzy from PyPI wheels).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.course-installed
PORT   ?= 8888
# Jupyter refuses to run as root (containers, CI machines) unless told it is deliberate.
ROOT_FLAG := $(if $(filter 0,$(shell id -u)),--allow-root,)
NBVAL  := --nbval --nbval-current-env --nbval-sanitize-with tests/nbval_sanitize.cfg \
          --nbval-cell-timeout=300 -p no:cacheprovider

.PHONY: setup lab test unit notebooks lint bench execute clean
.DEFAULT_GOAL := lab

setup: $(STAMP)
	@$(PY) -m course_helpers.core.build_interfaces

$(STAMP): environment.txt pyproject.toml
	@$(PYTHON) tools/check_platform.py
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r environment.txt
	$(PY) -m pip install --quiet --no-deps --no-build-isolation -e .
	@touch $(STAMP)

lab: setup
	$(VENV)/bin/jupyter lab --notebook-dir=notebooks --port=$(PORT) $(ROOT_FLAG)

test: setup
	$(PY) -m pytest tests -q
	$(PY) -m pytest $(NBVAL) notebooks -q

unit: setup
	$(PY) -m pytest tests -q

notebooks: setup
	$(PY) -m pytest $(NBVAL) notebooks -q

lint: setup
	$(VENV)/bin/ruff check course_helpers tests benchmarks tools notebooks

bench: setup
	$(PY) benchmarks/executor_throughput.py

# Re-execute the notebooks in place so the committed outputs are fresh (maintainers).
execute: setup
	$(PY) tools/execute_notebooks.py notebooks/*.ipynb

clean:
	rm -rf $(VENV) build install log tests/artifacts
