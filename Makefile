# Every target bootstraps .venv at the repository root from a fresh machine.  Another Python
# gets a virtual environment of its own: make test PYTHON=python3.12 VENV=.venv-py312
PYTHON ?= python3.11
VENV   ?= .venv
BIN    := $(VENV)/bin
HOST   ?= 127.0.0.1
PORT   ?= 8000
# pytest's arguments: every test by default
TESTS  ?=

.PHONY: run test test-py312 test-py313 fuzz load bench chart openapi lint clean image-test wheel

# One stamp per set of extras, so that `make test` does not pull in the benchmark stack.
$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.dev-installed: pyproject.toml | $(BIN)/python
	@# Open3D (tests/integrations/test_open3d.py) links against the system's libusb-1.0.
	@ldconfig -p | grep -q libusb-1.0 || (apt-get update -qq && apt-get install -y -qq libusb-1.0-0)
	@# The viewer's and the docs' browser tests (tests/service/test_viewer.py) drive Debian's
	@# Chromium through Playwright, which downloads no browser of its own.
	@test -x /usr/bin/chromium || (apt-get update -qq && \
	    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver)
	$(BIN)/python -m pip install --quiet -e ".[service,oracle,dev]"
	touch $@

$(VENV)/.bench-installed: pyproject.toml | $(BIN)/python
	@# Open3D links against the system's libusb-1.0.
	@ldconfig -p | grep -q libusb-1.0 || (apt-get update -qq && apt-get install -y -qq libusb-1.0-0)
	$(BIN)/python -m pip install --quiet -e ".[service,bench]"
	touch $@

run: $(VENV)/.dev-installed
	$(BIN)/raycore serve --host $(HOST) --port $(PORT)

test: $(VENV)/.dev-installed
	$(BIN)/python -m pytest $(TESTS)

# Python 3.12 and 3.13 (each on the PATH, else pyenv's newest of it) in .venv-py312 and
# .venv-py313: the library's and the service's tests that reach every kernel, in both
# precisions, and the service end to end.  Left out, for CI's time: the stability catalogue, the
# primitives' exact references and the service's fuzzing, which compile nothing that these do
# not.  PYTHON312 or PYTHON313 names another interpreter.
python_named = $(or $(shell python$(1) -c 'import sys; print(sys.executable)' 2>/dev/null),\
	$(lastword $(sort $(wildcard $(shell pyenv root 2>/dev/null)/versions/$(1).*/bin/python$(1)))))
PYTHON312 ?= $(call python_named,3.12)
PYTHON313 ?= $(call python_named,3.13)
OTHER_PYTHON_TESTS ?= tests/scene tests/bvh tests/service tests/test_camera.py tests/test_sensors.py tests/test_offset.py \
	tests/test_render.py tests/test_threading.py tests/test_info.py tests/test_compile_notice.py tests/test_warmup.py \
	tests/test_ray_bounds.py tests/test_target.py tests/commands tests/integrations/test_trimesh.py \
	tests/integrations/test_dask.py \
	--ignore tests/service/test_schemathesis.py --ignore tests/service/test_fuzz.py
test-py312 test-py313: test-py3%:
	@test -n "$(PYTHON3$*)" || (echo "$@ needs Python 3.$* (python3.$*, or pyenv's)"; exit 2)
	$(MAKE) test PYTHON="$(PYTHON3$*)" VENV=.venv-py3$* TESTS="$(OTHER_PYTHON_TESTS)"

# Schemathesis (`schemathesis run --checks all`, schemathesis.toml) against a real service with
# and without an API key, FUZZ_EXAMPLES cases per operation and phase: longer than the bounded
# run (60) inside `make test`; and the hypothesis fuzzers and hostile inputs.
FUZZ_EXAMPLES ?= 500
fuzz: $(VENV)/.dev-installed
	RAYCORE_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) $(BIN)/python -m pytest -p no:cacheprovider \
	    tests/service/test_schemathesis.py tests/service/test_fuzz.py tests/service/test_hostile.py

# Concurrent clients against a real uvicorn for 60 s (benchmarks/service_load.py): throughput,
# p50/p99 latency; fails on any error or when resident memory passes the store budget + margin.
load: $(VENV)/.dev-installed
	$(BIN)/python -m benchmarks.service_load --seconds 60

# raycore against Open3D and embreex, each library's own call timed (benchmarks/run.py: every
# shared mesh and nefertiti subdivided to 1.6M and 6.4M triangles, build time and memory, one
# thread against serial Embree); time per call from 1 to 1M rays (benchmarks/latency.py, with
# docs/latency.png); the HTTP service against in-process calls; compile times, cold and warm,
# and the time to a first answer (benchmarks/compile_time.py).  About 20 minutes on 2 cores;
# BENCH_ARGS=--no-large skips the large meshes, BENCH_ARGS=--quick is a smoke run.
BENCH_ARGS ?=
bench: $(VENV)/.bench-installed
	$(BIN)/python -m benchmarks.run $(BENCH_ARGS)
	$(BIN)/python -m benchmarks.latency $(filter --quick,$(BENCH_ARGS))
	$(BIN)/python -m benchmarks.dropin
	$(BIN)/python -m benchmarks.service_bench $(filter --quick,$(BENCH_ARGS))
	$(BIN)/python -m benchmarks.scene_file $(filter --no-large,$(BENCH_ARGS))
	$(BIN)/python -m benchmarks.dask_bench
	$(BIN)/python -m benchmarks.compile_time

# docs/speed-vs-accuracy.png and docs/model-what-you-need.png with their Markdown tables
# (benchmarks/speed_accuracy.py).  The error figures come from tests/stability's catalogue and
# the exact references in tests/primitives, so the test extras come with the benchmark stack.
chart: $(VENV)/.bench-installed $(VENV)/.dev-installed
	$(BIN)/python -m benchmarks.speed_accuracy

# The committed OpenAPI document, generated from the app (tests/service fail when it drifts).
openapi: $(VENV)/.dev-installed
	$(BIN)/raycore openapi --output openapi/openapi.json

# The container image: build docker/Dockerfile with podman (on a Debian bookworm base made with
# debootstrap, no registry needed) and exercise it as a container (docker/image_test.py).  Needs
# root; installs podman and debootstrap from Debian's packages when they are missing.
image-test:
	@command -v podman >/dev/null && command -v debootstrap >/dev/null || \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq podman debootstrap)
	$(PYTHON) docker/image_test.py

# dist/raycore-*.whl with raycore's kernels compiled in it (release/ship_kernels.py, for each
# CPU level this machine runs: x86-64-v4, x86-64-v3), so that a first answer after `pip install`
# loads them: one Python version per interpreter in WHEEL_PYTHONS, each in an environment with
# raycore's dependencies (make wheel WHEEL_PYTHONS=".venv/bin/python .venv-py313/bin/python").
# About 5 minutes a Python (both levels) on 2 cores.
WHEEL_PYTHONS ?= $(BIN)/python
wheel: $(VENV)/.dev-installed
	$(BIN)/python release/ship_kernels.py --dest dist --python $(WHEEL_PYTHONS)

lint: $(VENV)/.dev-installed
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) .venv-py312 .venv-py313 build dist *.egg-info
	find . -name __pycache__ -prune -exec rm -rf {} +
