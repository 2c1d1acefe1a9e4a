# Quick start (see README): `make reproduce` and `make test`, each on a fresh machine with only
# Python 3.11, pip and make. Both install the project into a virtual environment (.venv).
#
# What is installed is stamped in .venv: a target installs only when a source changed since.
# The C++ extension is built without build isolation in a kept CMake folder (build/<wheel
# tag>), so a reinstall recompiles only the C++ that changed (none after a Python-only edit).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
OUT ?= results
BUILD_DIR := build/{wheel_tag}
# every file the installed package is made of: a change reinstalls
SOURCES := pyproject.toml CMakeLists.txt $(shell find src -type f -not -name '*.so' \
	-not -name '*.pyc' -not -path '*/__pycache__/*' 2>/dev/null)
PIP_INSTALL := $(BIN)/python -m pip install --no-build-isolation -Cbuild-dir=$(BUILD_DIR)

.PHONY: install reproduce test test-slow docs bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip

# The build requirements of pyproject.toml's [build-system] (read from it), and CMake and
# Ninja from PyPI: no system CMake needed.
$(VENV)/.build-deps: $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install 'cmake>=3.25' ninja $$($(BIN)/python -c "import tomllib; \
		print(' '.join(tomllib.load(open('pyproject.toml', 'rb'))['build-system']['requires']))")
	touch $@

# The main job's dependencies only
$(VENV)/.installed: $(VENV)/.build-deps $(SOURCES)
	$(PIP_INSTALL) .
	touch $@

# With the test and docs extras (the suite builds the docs too)
$(VENV)/.installed-test: $(VENV)/.build-deps $(SOURCES)
	$(PIP_INSTALL) '.[test,docs]'
	touch $@ $(VENV)/.installed

install: $(VENV)/.installed-test

# reproduce owns $(OUT): --overwrite replaces its previous run there (only the files it wrote)
reproduce: $(VENV)/.installed
	$(BIN)/rrr-pin reproduce --realistic --out $(OUT) --overwrite

# two worker processes (pytest-xdist): the suite is CPU-bound and the machine has 2 cores
test: $(VENV)/.installed-test
	$(BIN)/python -m pytest -n 2

test-slow: $(VENV)/.installed-test
	$(BIN)/python -m pytest -n 2 -m slow

# API reference, README and notes, and the gallery of scripts/ (runs the two examples):
# docs/_build/html/index.html. Warnings are errors, as in CI.
docs: $(VENV)/.installed-test
	rm -rf docs/api  # autosummary's pages, regenerated: none left from a removed module
	$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html

clean:
	rm -rf $(VENV) build results docs/_build docs/api docs/gallery docs/sg_execution_times.rst
