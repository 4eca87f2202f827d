# The two commands a newcomer needs: `make demo` and `make test`.
# Both create .venv on first use from requirements-dev.txt; nothing installed by hand is assumed.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-$(shell cksum requirements-dev.txt | cut -d' ' -f1)

.PHONY: venv test demo bench package clean

venv: $(STAMP)

$(STAMP): requirements-dev.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check -r requirements-dev.txt
	rm -f $(VENV)/.installed-* && touch $@

test: $(STAMP)
	$(PY) -m pytest -q tests

demo: $(STAMP)
	$(PY) -m hemicube_radiosity demo --output-dir demo/out

BENCH_STAMP := $(VENV)/.bench-$(shell cksum requirements-bench.txt 2>/dev/null | cut -d' ' -f1)

$(BENCH_STAMP): $(STAMP) requirements-bench.txt
	$(PY) -m pip install -q --disable-pip-version-check -r requirements-bench.txt
	rm -f $(VENV)/.bench-* && touch $@

bench: $(BENCH_STAMP)
	$(PY) bench/run_all.py $(BENCH_ARGS)

package: $(STAMP)
	mkdir -p dist
	$(PY) $(VENV)/lib/python3.11/site-packages/bpy/5.0/scripts/addons_core/bl_pkg/cli/blender_ext.py build --source-dir . --output-dir dist

clean:
	rm -rf dist .pytest_cache
