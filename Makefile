# Set-up-and-run entry points. Needs python3.11 on PATH (bpy 5.0.x is built for Python 3.11).
PYTHON ?= python3.11
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: demo test bench extension clean

$(VENV)/.installed: requirements.txt requirements-dev.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements-dev.txt
	touch $@

demo: $(VENV)/.installed
	$(PY) scripts/demo.py

test: $(VENV)/.installed
	$(PY) -m pytest -q tests

bench: $(VENV)/.installed
	$(PY) scripts/benchmark.py --json out/benchmark.json

extension: $(VENV)/.installed
	$(PY) scripts/build_extension.py

clean:
	rm -rf $(VENV) out build dist .pytest_cache
