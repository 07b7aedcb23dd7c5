# Set-up-and-run entry points. Needs python3.11 on PATH (bpy 5.0.x is built for Python 3.11).
PYTHON ?= python3.11
VENV ?= .venv
PY := $(VENV)/bin/python
# The second test leg (CI): Blender 5.2 LTS as a module on Python 3.13, in its own environment.
PYTHON313 ?= $(firstword $(wildcard $(shell pyenv root 2>/dev/null)/versions/3.13.*/bin/python3.13) $(shell command -v python3.13 2>/dev/null))
VENV313 ?= .venv313
# The oldest Blender the manifest claims (CI): Blender 4.2 LTS as a module on Python 3.11.
VENV42 ?= .venv42

.PHONY: demo test test313 test42 test-gui docs-pictures bench extension repo clean

$(VENV)/.installed: requirements.txt requirements-dev.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements-dev.txt
	touch $@

$(VENV313)/.installed: requirements-py313.txt
	$(PYTHON313) -m venv $(VENV313)
	$(VENV313)/bin/python -m pip install --quiet --upgrade pip
	$(VENV313)/bin/python -m pip install --quiet -r requirements-py313.txt
	touch $@

$(VENV42)/.installed: requirements.txt requirements-bpy42.txt
	$(PYTHON) -m venv $(VENV42)
	$(VENV42)/bin/python -m pip install --quiet --upgrade pip
	$(VENV42)/bin/python -m pip install --quiet -r requirements-bpy42.txt
	touch $@

demo: $(VENV)/.installed
	$(PY) scripts/demo.py

test: $(VENV)/.installed
	$(PY) -m pytest -q tests

test313:
	@if [ -z "$(PYTHON313)" ] || ! "$(PYTHON313)" -c "import sys; assert sys.version_info[:2] == (3, 13)" 2>/dev/null; then \
		echo "NOTICE: no Python 3.13 on this machine: the Blender 5.2 (bpy 5.2.x, Python 3.13) test leg is skipped"; \
	else \
		$(MAKE) --no-print-directory $(VENV313)/.installed PYTHON313="$(PYTHON313)" && \
		$(VENV313)/bin/python -m pytest -q tests; \
	fi

test42: $(VENV42)/.installed
	$(VENV42)/bin/python -m pytest -q tests

# Measure the drag and the quality again and rewrite docs/benchmarks.md from their JSON (with
# bench/results/scale.json as last measured: scripts/benchmark_scale.py is long, run it by hand).
bench: $(VENV)/.installed
	$(PY) scripts/benchmark_drag.py --busy --json bench/results/drag.json
	$(PY) scripts/benchmark_quality.py --poses 100 --json bench/results/quality.json
	$(PY) scripts/benchmark_quality.py --rigs --json bench/results/rigs.json
	$(PY) scripts/benchmark_quality.py --proxy-angles --json bench/results/proxy_angles.json
	$(PY) scripts/benchmark_riders.py --json bench/results/riders.json
	$(PY) scripts/benchmark_page.py

extension: $(VENV)/.installed
	$(PY) scripts/build_extension.py

# A static extension repository for a studio (docs/studio.md): every platform's zip and Blender's
# index.json in dist/repo/; older versions there move to dist/repo/archive/.
repo: $(VENV)/.installed
	$(PY) scripts/build_repo.py

clean:
	rm -rf $(VENV) $(VENV313) $(VENV42) out build dist .pytest_cache

# The GUI tests in a real Blender window (Debian's blender 5.2.x in a cached chroot made with
# debootstrap, or the Blender named by BLENDER=): installs the linux-x64 zip with
# `blender --command extension install-file`, then drives the add-on with events under Xvfb.
test-gui: $(VENV)/.installed
	$(PY) scripts/build_extension.py --platforms linux-x64
	$(PY) scripts/gui_test.py

# The docs' pictures of the window (docs/window_*.png), taken the same way.
docs-pictures: $(VENV)/.installed
	$(PY) scripts/build_extension.py --platforms linux-x64
	$(PY) scripts/gui_test.py --pictures docs
