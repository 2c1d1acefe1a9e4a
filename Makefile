# Quick start (see README): `make reproduce` and `make test`, each on a fresh machine with only
# Python 3.11, pip and make. Both install the project into a virtual environment (.venv).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
OUT ?= results

.PHONY: install reproduce test test-slow docs bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip

install: $(BIN)/python
	$(BIN)/python -m pip install '.[test,docs]'

# reproduce owns $(OUT): --overwrite replaces its previous run there (only the files it wrote)
reproduce: install
	$(BIN)/rrr-pin reproduce --out $(OUT) --overwrite

# two worker processes (pytest-xdist): the suite is CPU-bound and the machine has 2 cores
test: install
	$(BIN)/python -m pytest -n 2

test-slow: install
	$(BIN)/python -m pytest -n 2 -m slow

# API reference, README and notes, and the gallery of scripts/ (runs the two examples):
# docs/_build/html/index.html. Warnings are errors, as in CI.
# Installs the project with its docs extra unless `make install` (or test) already did: a second
# install would compile the extension again.
docs: $(BIN)/python
	$(BIN)/python -c "import rrr_pin, sphinx, numpydoc, sphinx_gallery, myst_parser" 2>/dev/null \
		|| $(BIN)/python -m pip install '.[test,docs]'
	rm -rf docs/api  # autosummary's pages, regenerated: none left from a removed module
	$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html

clean:
	rm -rf $(VENV) build results docs/_build docs/api docs/gallery docs/sg_execution_times.rst
