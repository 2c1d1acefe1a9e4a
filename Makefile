# Quick start (see README): `make reproduce` and `make test`, each on a fresh machine with only
# Python 3.11, pip and make. Both install the project into a virtual environment (.venv).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
OUT ?= results

.PHONY: install reproduce test test-slow bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip

install: $(BIN)/python
	$(BIN)/python -m pip install '.[test]'

# reproduce owns $(OUT): --overwrite replaces its previous run there (only the files it wrote)
reproduce: install
	$(BIN)/rrr-pin reproduce --out $(OUT) --overwrite

test: install
	$(BIN)/python -m pytest

test-slow: install
	$(BIN)/python -m pytest -m slow

clean:
	rm -rf $(VENV) build results
