# The two commands a newcomer needs: `make demo` and `make test`.
# Both create .venv on first use from requirements-dev.txt; nothing installed by hand is assumed.
#
#   make test        the whole suite on Blender 5.0 (bpy 5.0.1), after `make viewer-deps`
#   make viewer-deps what the viewer tests (tests/blender/test_viewer.py, test_lightmap_viewer.py) need:
#                    Debian's chromium, node and npm (apt-get, as root) and the npm packages
#                    tests/support/viewer/package-lock.json pins
#   make test-lts    the suite on Blender 4.2 LTS and 4.5 LTS (.venv-4.2, .venv-4.5; not part of `make test`)
#   make demo        bake the Cornell box into demo/out/
#   make bench       benchmarks (docs/performance.md)
#   make bench-real  the real scenes of ../shared/scenes alone (BENCH_ARGS="--quick" or "--scenes a,b")
#   make bench-lightmap  the lightmap target on a real scene against Cycles' image bake (BENCH_ARGS="--ref-spp 256")
#   make gallery     their pictures beside Cycles' (docs/gallery.md; BENCH_ARGS="--all" or "--scenes a,b")
#   make package     one extension zip per platform in dist/, each with its embreex wheel
#   make clean       dist/, wheels/ and caches;  make distclean: also every .venv*
#
# bpy is published for Python 3.11 only: PYTHON must be a 3.11 (default: python3.11 on PATH).
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
PIP_Q  := -q --disable-pip-version-check

.PHONY: venv test viewer-deps test-lts lts-venvs demo bench bench-real bench-lightmap gallery package wheels clean distclean

# $(call ensure_venv,DIR,REQUIREMENTS): (re)build DIR unless it is a working Python 3.11 venv that
# has installed exactly REQUIREMENTS (a stamp named after the file's checksum, written only when
# pip succeeded). A venv whose python is missing, broken or not 3.11 is removed and rebuilt.
define ensure_venv
@if ! $(1)/bin/python -c 'import sys; assert sys.version_info[:2] == (3, 11)' 2>/dev/null; then \
	if [ -e $(1) ]; then echo "make: $(1) is broken or not Python 3.11: rebuilding it"; rm -rf $(1); fi; \
	if ! "$(PYTHON)" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then \
		echo "make: Python 3.11 is needed (bpy exists for 3.11 only); '$(PYTHON)' is $$("$(PYTHON)" --version 2>/dev/null || echo "not found"). Run: make PYTHON=/path/to/python3.11 $(MAKECMDGOALS)" >&2; \
		exit 1; \
	fi; \
	echo "make: creating $(1) with $(PYTHON)"; \
	"$(PYTHON)" -m venv $(1) || exit 1; \
fi; \
stamp=$(1)/.installed-$$(cksum $(2) | cut -d' ' -f1); \
if [ ! -e $$stamp ]; then \
	echo "make: installing $(2) into $(1)"; \
	$(1)/bin/python -m pip install $(PIP_Q) -r $(2) || exit 1; \
	rm -f $(1)/.installed-*; touch $$stamp; \
fi
endef

venv:
	$(call ensure_venv,$(VENV),requirements-dev.txt)

# The viewer test installs nothing: its browser and npm packages come from here. Where they cannot
# be had (not root, offline) the suite still runs and that test is skipped, naming this target.
test: venv
	@$(MAKE) --no-print-directory viewer-deps || echo "make: viewer-deps failed: tests/blender/test_viewer.py and test_lightmap_viewer.py will be skipped" >&2
	$(PY) -m pytest -q tests

VIEWER_DIR := tests/support/viewer
APT_GET    := DEBIAN_FRONTEND=noninteractive apt-get

viewer-deps: $(VIEWER_DIR)/node_modules/.package-lock.json
	@command -v chromium >/dev/null || command -v chromium-browser >/dev/null || { \
		[ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null || { echo "make: chromium is missing: run 'apt-get install chromium' as root" >&2; exit 1; }; \
		$(APT_GET) update -q && $(APT_GET) install -y -q --no-install-recommends chromium; }

# npm ci rewrites node_modules/.package-lock.json: newer than the lock file once they agree
$(VIEWER_DIR)/node_modules/.package-lock.json: $(VIEWER_DIR)/package-lock.json
	@command -v npm >/dev/null || { \
		[ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null || { echo "make: node and npm are missing: run 'apt-get install nodejs npm' as root" >&2; exit 1; }; \
		$(APT_GET) update -q && $(APT_GET) install -y -q --no-install-recommends nodejs npm; }
	cd $(VIEWER_DIR) && PUPPETEER_SKIP_DOWNLOAD=1 npm ci --no-audit --no-fund --ignore-scripts

demo: venv
	$(PY) -m hemicube_radiosity demo --output-dir demo/out

# ---------------------------------------------------------------- Blender 4.2 LTS and 4.5 LTS
# Each LTS venv runs the whole suite; the add-on's own 4.x gaps are listed in docs/pipeline.md.
LTS := 4.2 4.5

lts-venvs:
	$(call ensure_venv,.venv-4.2,requirements-lts-4.2.txt)
	$(call ensure_venv,.venv-4.5,requirements-lts-4.5.txt)

test-lts: lts-venvs
	@rc=0; for v in $(LTS); do \
		echo "##### Blender $$v (bpy $$(.venv-$$v/bin/python -c 'import importlib.metadata as m; print(m.version("bpy"))'))"; \
		.venv-$$v/bin/python -m pytest -q tests $(LTS_ARGS) || rc=1; \
	done; exit $$rc

# ---------------------------------------------------------------- benchmarks
define ensure_bench
@stamp=$(VENV)/.bench-$$(cksum requirements-bench.txt | cut -d' ' -f1); \
if [ ! -e $$stamp ]; then \
	$(PY) -m pip install $(PIP_Q) -r requirements-bench.txt || exit 1; \
	rm -f $(VENV)/.bench-*; touch $$stamp; \
fi
endef

bench: venv
	$(ensure_bench)
	$(PY) bench/run_all.py $(BENCH_ARGS)

bench-real: venv
	$(ensure_bench)
	$(PY) bench/real_scenes.py $(BENCH_ARGS)

bench-lightmap: venv
	$(ensure_bench)
	$(PY) bench/lightmap_real.py $(BENCH_ARGS)

gallery: venv
	$(ensure_bench)
	$(PY) bench/gallery.py $(BENCH_ARGS)

# ---------------------------------------------------------------- extension zips
# One zip per platform (blender_ext.py build --split-platforms), each bundling the embreex wheel
# for that platform. The wheels are downloaded into wheels/ (git-ignored) by `make wheels`, under
# the names blender_manifest.toml lists; blender_ext.py is found inside the installed bpy module.
EMBREEX := $(shell sed -n 's/^embreex==//p' requirements-dev.txt)
WHEEL_PLATFORMS := manylinux_2_28_x86_64 win_amd64 macosx_13_0_arm64 macosx_13_0_x86_64
BLENDER_EXT = $(shell $(PY) -c 'import importlib.util as u, glob, os; print(*glob.glob(os.path.join(os.path.dirname(u.find_spec("bpy").origin), "*", "scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py")))')

MANIFEST_WHEELS = $(shell sed -n 's|^ *"\./\(wheels/[^"]*\.whl\)".*|\1|p' blender_manifest.toml)

# WHEEL_PY: any Python with pip (the tests pass their own).
WHEEL_PY ?= $(PY)

wheels:
	@if ls $(MANIFEST_WHEELS) >/dev/null 2>&1; then exit 0; fi; \
	mkdir -p wheels; \
	for plat in $(WHEEL_PLATFORMS); do \
		$(WHEEL_PY) -m pip download $(PIP_Q) --no-deps --only-binary=:all: --platform $$plat \
			--python-version 3.11 --implementation cp -d wheels embreex==$(EMBREEX) || exit 1; \
	done; \
	for w in $(MANIFEST_WHEELS); do \
		[ -f $$w ] || { echo "make: blender_manifest.toml lists $$w but pip fetched another name (is embreex==$(EMBREEX) the version it names?)" >&2; exit 1; }; \
	done

package: venv wheels
	@[ -f "$(BLENDER_EXT)" ] || { echo "make: no blender_ext.py in the bpy module of $(VENV)" >&2; exit 1; }
	@rm -rf dist && mkdir -p dist
	$(PY) $(BLENDER_EXT) build --source-dir . --output-dir dist --split-platforms
	@ls -l dist

clean:
	rm -rf dist wheels .pytest_cache bench/out
	find . -name __pycache__ -type d -not -path './.venv*' -prune -exec rm -rf {} +

distclean: clean
	rm -rf .venv .venv-4.2 .venv-4.5
