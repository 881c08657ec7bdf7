# The README's commands. Each target sets up .venv itself (Python 3.11 + requirements-dev.txt).
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.requirements-dev.stamp
PYTEST_ARGS ?=

.PHONY: venv test test-fast lint extension demo bench pictures clean

venv: $(STAMP)

# Re-installs only when requirements-dev.txt changes (or the venv is new).
$(STAMP): requirements-dev.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -r requirements-dev.txt
	touch $@

# The whole suite: engine, Blender and packaging tests, including the slow install test; one worker per core, each
# taking whole test files (kernels are compiled once first: tests/warm_kernels.py).
PARALLEL := -n auto --dist loadfile
test: venv
	$(PY) -m pytest $(PARALLEL) $(PYTEST_ARGS)

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
