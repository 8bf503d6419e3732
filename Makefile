# The set-up contract: `make demo` and `make test` create .venv when missing.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
# CPU build of PyTorch from the local wheel cache; a looser pin pulls CUDA.
TORCH_PIN := torch==2.13.0

.PHONY: venv demo test test-slow house bench bench-training bench-algorithms images lint format clean

venv: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet $(TORCH_PIN)
	$(BIN)/python -m pip install --quiet -e '.[dev,train,sweep]'
	$(BIN)/python -m quadsitl.warmup
	touch $@

demo: venv
	$(BIN)/quadsitl demo

# Test processes in parallel (pytest-xdist): two per core, as most tests wait on sockets
# and simulators; TEST_WORKERS=0 runs the suite in one. The tests that start a Ray of
# their own share one process (xdist_group "ray"), so that two Rays never compete for the
# cores at once. The 20 slowest tests are listed at the end.
TEST_WORKERS ?= $(shell echo $$(( 2 * $$(nproc 2>/dev/null || echo 2) )))
test: venv
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadgroup --durations=20

# MAVProxy's core for its slow test, without the GUI and vision packages it lists
# (OpenCV, VTK, wxPython): the simulator's tests only drive its command line.
test-slow: venv
	$(BIN)/python -m pip install --quiet --no-deps 'MAVProxy>=1.8.75'
	$(BIN)/python -m pip install --quiet defusedxml pynmeagps pyserial
	$(BIN)/python -m pytest -q -m slow

# The house's measures (files to add a task, largest file, import cycles, ...);
# `make house SUITE=--suite` also times `make test` on a loaded machine.
house: venv
	$(BIN)/python benchmarks/house.py $(SUITE)

bench: venv
	$(BIN)/python benchmarks/physics.py
	$(BIN)/python benchmarks/envs.py
	$(BIN)/python benchmarks/sitl.py
	$(BIN)/python benchmarks/sitl_load.py
	$(BIN)/python benchmarks/ardupilot.py
	$(BIN)/python benchmarks/px4.py
	$(BIN)/python benchmarks/flight_stack_env.py
	$(BIN)/python benchmarks/flight_stack_real.py
	$(BIN)/python benchmarks/mavlink_env.py
	$(BIN)/python benchmarks/mavlink_training.py
	$(BIN)/python benchmarks/sb3_vs_ppo.py
	$(BIN)/python benchmarks/replay.py
	$(BIN)/python benchmarks/flight_logs.py
	$(BIN)/python benchmarks/live_fleet.py
	$(BIN)/python benchmarks/export.py
	$(BIN)/python benchmarks/robustness.py
	$(BIN)/python benchmarks/reference_pid.py

bench-training: venv
	$(BIN)/python benchmarks/training.py

bench-algorithms: venv
	$(BIN)/python benchmarks/sweep.py
	$(BIN)/python benchmarks/algorithms.py
	$(BIN)/python benchmarks/algorithms.py --preset paper --tasks hover

# The pictures of the docs, from real runs: Rerun's, rendered headless (without a GPU:
# Debian's mesa-vulkan-drivers), and the shipped policies' trajectories. Into
# build/images/; `make images DOCS=1` also replaces the tracked ones in docs/images/.
images: venv
	$(BIN)/python benchmarks/images.py $(if $(DOCS),--docs)
	$(BIN)/python benchmarks/figures.py $(if $(DOCS),--docs)

lint: venv
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy quadsitl policies gcs_tools --ignore-missing-imports

format: venv
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
