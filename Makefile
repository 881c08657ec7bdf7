# The README's commands. Each target sets up .venv itself (Python 3.11 + requirements-dev.txt).
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.requirements-dev.stamp
PYTEST_ARGS ?=
# Warp's compiled kernels for every target here, the tests', the demo's and the benchmarks' alike (git-ignored): a
# checkout compiles them once.
export WARP_CACHE_PATH ?= $(CURDIR)/.warp-cache

# The older Blenders the manifest names (blender_version_min = 4.2): 4.2 LTS and 4.5 LTS, each in .venv-blender-<v>
# with the pinned bpy of requirements-blender-<v>.txt and the same warp-lang as .venv (so they share .warp-cache/).
OLDER_BLENDERS := 4.2 4.5
OLDER_TESTS := $(OLDER_BLENDERS:%=test-blender-%)

.PHONY: venv test test-main test-older $(OLDER_TESTS) test-fast lint extension demo bench pictures clean

venv: $(STAMP)

# Re-installs only when requirements-dev.txt changes (or the venv is new).
$(STAMP): requirements-dev.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -r requirements-dev.txt
	touch $@

# The same for each older Blender's venv.
.venv-blender-%/.requirements.stamp: requirements-blender-%.txt
	test -x .venv-blender-$*/bin/python || $(PYTHON) -m venv .venv-blender-$*
	.venv-blender-$*/bin/python -m pip install -r $<
	touch $@

# The whole suite on Blender 5.0 (engine, Blender and packaging tests, including the slow install test), one worker
# per core, each taking whole test files (kernels are compiled once first: tests/warm_kernels.py; the older Blenders
# find them compiled); then the Blender tests on 4.2 and 4.5. The older Blenders leave out the tests marked
# newest_blender: the benchmark's references (5.0's tools); the batch script's process management (timeouts, kills,
# reruns, Dask) and options that only reach the add-on's pipeline (thickness, offset, shell, --keep-faces, objects
# checked by name), whose Blender calls the other batch tests make on every version; and engine or cache work that
# only goes through the add-on again (a blend at voxel 1/256, two of the three operations on real meshes, fields placed
# for moved or duplicated operands, the page pool's limit), whose operator calls other tests make on every version.
# Every bpy call the add-on and the batch script make is still made on each Blender: 1.5 minutes for both here.
PARALLEL := -n auto --dist loadfile
test: test-main test-older

# The older Blenders side by side, one process each, their output one after the other (90 s here, against 105 s one
# after the other on a worker per core: a worker's start-up costs as much as it saves on a suite this short).
test-older: $(OLDER_BLENDERS:%=.venv-blender-%/.requirements.stamp)
	$(MAKE) --no-print-directory -j2 --output-sync=target $(OLDER_TESTS) PARALLEL="-p no:xdist"

test-main: venv
	$(PY) -m pytest $(PARALLEL) $(PYTEST_ARGS)

$(OLDER_TESTS): test-blender-%: .venv-blender-%/.requirements.stamp
	.venv-blender-$*/bin/python -m pytest $(PARALLEL) -m "not newest_blender" tests/blender $(PYTEST_ARGS)

# Everything but the slow tests (the install test builds a 150 MB zip and installs it in a bare bpy).
test-fast: venv
	$(PY) -m pytest $(PARALLEL) -m "not slow" $(PYTEST_ARGS)

lint: venv
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

# One installable zip per platform in dist/, with the platform's warp-lang wheel (downloaded into wheels/).
extension: venv
	$(PY) tools/build_extension.py --output-dir dist

# The main job: a headless SDF boolean on the bundled sample meshes (cow minus sphere) that writes the result mesh
# and a debug volume of its field, and prints what it did.
demo: venv
	$(PY) aasdf_batch.py --operation difference --inputs samples/cow.obj samples/sphere.obj --resolution 256 \
		--output demo-output/cow-minus-sphere.ply --debug-volume demo-output/cow-minus-sphere.vdb

# Side-by-side benchmarks against Blender's own tools, written to bench/RESULTS.md; tens of minutes.
bench: venv
	$(PY) bench/run_all.py

# The README's pictures (docs/images/*.png), rendered headless with Cycles on the CPU.
pictures: venv
	$(PY) tools/render_pictures.py

clean:
	rm -rf build dist .warp-cache .pytest_cache .ruff_cache
