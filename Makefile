# cloth_sim: `make run` and `make test` install everything into .venv on first use (and again only when
# requirements.txt or the package metadata change), then run the node's scene or the test suite.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# the package's own interfaces (msg/, srv/) and the standard ones no wheel has (interfaces/), generated
# with rosidl + cmake from the wheels: tools/build_interfaces.py
MSGS   := build/interfaces/.built
# numba's kernels compiled into their on-disk cache (again when the package's code changes: a
# fraction of a second when the cache holds them; from an empty cache, kernels.compile_kernels'
# three parts each in a process of its own, since numba compiles on one core, beside the
# interfaces and the site; then one call finds them all in the cache), and the package's
# bytecode: these machines set PYTHONDONTWRITEBYTECODE=1, so without it every process (a node, a CLI, a Ray worker) compiled
# the package's modules again as it imported them (0.2-0.5 s a process: docs/BENCHMARKS.md §11)
KERNELS := $(VENV)/.kernels
# scipy's sparse solvers and numpy's BLAS oversubscribe 2 cores badly when threaded.
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export ROS_LOG_DIR ?= $(CURDIR)/.ros_log

SCENE    ?= hanging
# the kernels and the interfaces build side by side (each about a minute and a half on a fresh
# install here; the interfaces' cmake steps leave a core idle)
MAKEFLAGS += --jobs=2

.PHONY: install run test lint docs fuzz bench bench-peers bench-robots bench-learning gpu test-gpu \
	bench-gpu device-wheels clean
install: $(STAMP) $(KERNELS) $(MSGS)

# uv (pinned in requirements.txt, installed by pip first) installs the pinned set: 23 s where pip
# took 118 here, the same files (docs/BENCHMARKS.md §11). It copies from its cache instead of
# linking (tools/build_interfaces.py edits some wheels' CMake files in place) and byte-compiles
# every wheel as pip did: these machines set PYTHONDONTWRITEBYTECODE=1, so without it every
# process (Ray's workers, the nodes) would compile what it imports
UV_PIN := $(shell grep -E '^uv==' requirements.txt | cut -d' ' -f1)
UV     := $(VENV)/bin/uv pip install --python $(PY) --link-mode copy --compile-bytecode -q
$(STAMP): requirements.txt setup.py pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --disable-pip-version-check -q $(UV_PIN)
	$(UV) -r requirements.txt
	$(PY) -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation \
		--config-settings editable_mode=compat -e .
	@touch $@

$(KERNELS): $(STAMP) $(shell find cloth_sim -name '*.py')
	$(PY) -m compileall -q cloth_sim
	pids=; for part in grid_contacts contacts steps; do \
		$(PY) -c "from cloth_sim.kernels import compile_kernels as c; \
			print(f'kernels ($$part) compiled in {c(\"$$part\"):.1f} s')" & pids="$$pids $$!"; \
	done; for pid in $$pids; do wait $$pid || exit 1; done
	$(PY) -c "from cloth_sim.kernels import compile_kernels as c; print(f'kernels: all in the cache, {c():.1f} s')"
	@touch $@

$(MSGS): $(STAMP) msg/Stats.msg $(wildcard srv/*.srv) CMakeLists.txt package.xml tools/build_interfaces.py \
		tools/python_only_interfaces.cmake \
		$(wildcard interfaces/*/*.txt interfaces/*/package.xml interfaces/*/*/*.msg interfaces/*/*/*.srv interfaces/*/*/*.action) \
		$(wildcard launch/* config/*.yaml config/scenes/*.yaml)
	$(PY) tools/build_interfaces.py
	@touch $@

run: install
	$(VENV)/bin/cloth_sim_node --ros-args --params-file config/cloth_sim.yaml -p scene:=$(SCENE)

# the core's tests in a run of their own (test/core/conftest.py fails a test after which rclpy is
# imported), then the adapters' and the node's, then the tests that start Ray (sweeps, datasets,
# the examples) in a run of their own, so the node's real-time checks never share the cores with
# Ray's workers; PYTEST_WORKERS test processes (pytest-xdist, a file to a worker; each worker's DDS
# domains its own: test/ros/ros_helpers.py), 0 for one process
PYTEST_WORKERS ?= 2
PYTEST_N := $(if $(filter 0,$(PYTEST_WORKERS)),,-n $(PYTEST_WORKERS) --dist loadfile)
RAY_TESTS := test/adapters/test_dataset.py test/adapters/test_sweep.py test/adapters/test_examples.py
test: install
	$(PY) -m pytest $(PYTEST_N) test/core $(PYTEST_ARGS)
	$(PY) -m pytest $(PYTEST_N) test/adapters test/ros $(addprefix --ignore=,$(RAY_TESTS)) $(PYTEST_ARGS)
	$(PY) -m pytest $(PYTEST_N) $(RAY_TESTS) $(PYTEST_ARGS)

# the CUDA backend (cloth_sim.cuda, device="cuda"): numba-cuda and the CUDA 13 wheels it loads
# (requirements-gpu.txt, ~200 MB), never part of make test. test-gpu runs the kernels' tests on the
# GPU, or on numba-cuda's simulator where none is found (tiny cloths, ~30 s), then compiles every
# kernel to PTX for sm_90 (NVVM from the wheels: no GPU needed); bench-gpu prints the GPU's figures
# (docs/gpu.md) and needs a GPU
GPU := $(VENV)/.gpu
# (a test to a worker: the simulator's tests and the two precisions' compile checks are independent)
GPU_N := $(if $(filter 0,$(PYTEST_WORKERS)),,-n $(PYTEST_WORKERS) --dist load)
gpu: $(GPU)
$(GPU): $(STAMP) requirements-gpu.txt
	$(UV) -r requirements-gpu.txt
	@touch $@

test-gpu: install $(GPU)
	@if $(PY) -c "from numba import cuda; raise SystemExit(not cuda.is_available())" 2>/dev/null; \
	then sim=0; echo "test-gpu: on the GPU"; else sim=1; echo "test-gpu: no GPU, on numba-cuda's simulator"; fi; \
	NUMBA_ENABLE_CUDASIM=$$sim $(PY) -m pytest $(GPU_N) test/gpu/sim $(PYTEST_ARGS)
	NUMBA_ENABLE_CUDASIM=0 $(PY) -m pytest $(GPU_N) test/gpu/ptx $(PYTEST_ARGS)

bench-gpu: install $(GPU)
	$(VENV)/bin/cloth-sim bench gpu

# the wheels tools/device_check.sh installs on a GPU machine lent by the device tool (Python 3.12,
# numpy, numba and numba-cuda there, no network): the pinned versions of requirements.txt for
# CPython 3.12 on x86-64 Linux (gymnasium and its three for the vector env; yourdfpy, lxml, six
# and trimesh for the robots on the device), ~45 MB, in .device/wheels (ignored; carry .device)
DEVICE_WHEELS := scipy qdldl PyYAML pytest pluggy iniconfig packaging Pygments gymnasium \
	cloudpickle farama-notifications typing_extensions yourdfpy lxml six trimesh
device-wheels: $(STAMP)
	mkdir -p .device/wheels
	$(PY) -m pip download -q -d .device/wheels --no-deps --only-binary=:all: \
		--python-version 3.12 --implementation cp --abi cp312 --abi none \
		--platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform any \
		$(foreach p,$(DEVICE_WHEELS),$(shell grep -E '^$(p)==' requirements.txt | cut -d' ' -f1))

# ruff (pinned in requirements.txt, configured in pyproject.toml): the linter and the formatter's check
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

# the site (docs/conf.py: Sphinx, MyST pages, autodoc, tables generated from the code) into
# build/docs/html; warnings are errors. rosdoc2 builds the same pages (rosdoc2.yaml).
docs: $(STAMP) $(MSGS)
	$(PY) -m sphinx -W --keep-going -q -b html docs build/docs/html
	@echo "the site: build/docs/html/index.html"

# a long seeded fuzz of the live node through its parameter services; prints its figures (~8 min)
FUZZ_SETS ?= 5000
fuzz: install
	ROS_DOMAIN_ID=$${ROS_DOMAIN_ID:-97} $(PY) test/fuzz_node.py --sets $(FUZZ_SETS) --seed 1

# the full benchmark run docs/BENCHMARKS.md reports (about 10 minutes on 2 cores)
bench: install
	for b in work-precision stability scaling; do $(VENV)/bin/cloth-sim bench $$b --out docs/bench/$$b || exit 1; done

# NVIDIA Warp's CPU cloth kernel, Newton's VBD and MuJoCo's flex beside ours (installs the pinned
# optional extra, ~550 MB: warp-lang, newton, mujoco; about 12 minutes)
bench-peers: install
	$(UV) -r requirements-peers.txt
	$(VENV)/bin/cloth-sim bench peers
	$(VENV)/bin/cloth-sim bench vbd-peers
	$(VENV)/bin/cloth-sim bench franka-peer
	$(VENV)/bin/cloth-sim bench flex-peer

# robots in the scene: forward kinematics, mesh colliders against primitives, the robot_sweep
# scene, and a Panda and a UR5 from example-robot-data (requirements-robots.txt, ~431 MB, never in
# make test) swung through its cloth (about 2 minutes)
bench-robots: install
	$(UV) -r requirements-robots.txt
	$(PY) -m cloth_sim.bench.robot --published

# a LeRobot dataset of ClothFold's scripted policy (100 episodes, about 2 minutes), then LeRobot's ACT
# trained on it on the CPU and played against the scripted and a random policy (about 5 minutes),
# in .venv-learning: LeRobot and torch (requirements-learning.txt, ~8 GB, its own venv: see there)
LVENV ?= .venv-learning
bench-learning: install
	$(VENV)/bin/cloth-sim dataset ClothFold -o build/datasets/ClothFold --episodes 100 --no-progress
	@test -x $(LVENV)/bin/python || $(PYTHON) -m venv $(LVENV)
	$(LVENV)/bin/python -m pip install --disable-pip-version-check -q -r requirements-learning.txt
	$(LVENV)/bin/python -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation \
		--config-settings editable_mode=compat -e .
	HF_HUB_OFFLINE=1 $(LVENV)/bin/python examples/learning/train_act.py --dataset build/datasets/ClothFold

clean:
	rm -rf $(VENV) $(LVENV) .ros_log build install log *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
