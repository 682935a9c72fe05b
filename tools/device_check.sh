#!/usr/bin/env bash
# The CUDA backend's checks and figures in one run on a GPU machine lent by the `device` tool
# (docs/gpu.md, "On a lent GPU"): from the repository root there, with the Python 3.12 wheels that
# `make device-wheels` put in .device/wheels carried along (the machine has Python 3.12 with numpy,
# numba and numba-cuda, and no network). Everything it prints goes to $OUT as well:
#   gpu.txt    nvidia-smi and the versions
#   tests.log  the kernels' tests (test/gpu/sim) on the GPU itself, not the simulator; the node's
#              test needs ROS 2, which that machine has not, and is left out
#   bench.log  cloth-sim bench gpu's five tables (docs/gpu.md)
# Each part runs under its own time limit (seconds: TESTS_S, BENCH_S), so that the figures come back
# within one call of the tool (10 minutes at most). DEVICE_CHECK_SIMULATOR=1 runs the same script on
# numba-cuda's simulator with tiny sizes: what a machine without a GPU can check of it
# (DEVICE_PYTHON: a Python 3.12 with numpy, numba and numba-cuda to run it with; python3 there).
set -uo pipefail
OUT=${OUT:-$PWD/.device/out}
mkdir -p "$OUT"
TESTS_S=${TESTS_S:-240}
BENCH_S=${BENCH_S:-270}
SIM=${DEVICE_CHECK_SIMULATOR:-0}
export PYTHONUNBUFFERED=1 NUMBA_ENABLE_CUDASIM=$SIM OPENBLAS_NUM_THREADS=1

# the carried wheels unpacked onto the path, over the machine's own numpy, numba and numba-cuda
# (a wheel is a zip of what it installs: no pip or venv needed there)
py=${DEVICE_PYTHON:-python3}
lib=/tmp/cloth_sim_lib
mkdir -p "$lib"
for w in .device/wheels/*.whl; do
    "$py" -m zipfile -e "$w" "$lib" || exit 1
done
export PYTHONPATH=$lib:$PWD

{
    date -u
    nvidia-smi || echo "no nvidia-smi here"
    "$py" -c "import sys, numpy, numba, scipy; from numba import cuda; \
print(sys.version.split()[0], 'numpy', numpy.__version__, 'numba', numba.__version__, \
'scipy', scipy.__version__); print('cuda available:', cuda.is_available())"
    "$py" -c "import numba_cuda; print('numba-cuda', numba_cuda.__version__)" 2>/dev/null
} 2>&1 | tee "$OUT/gpu.txt"

echo "== tests (limit ${TESTS_S} s)" | tee "$OUT/tests.log"
timeout "$TESTS_S" "$py" -m pytest -q -p no:cacheprovider test/gpu/sim \
    --ignore=test/gpu/sim/test_node_on_cuda.py 2>&1 | tee -a "$OUT/tests.log"
echo "tests exit: ${PIPESTATUS[0]}" | tee -a "$OUT/tests.log"

echo "== cloth-sim bench gpu (limit ${BENCH_S} s)" | tee "$OUT/bench.log"
if [ "$SIM" = 1 ]; then
    args="simulator=True, seconds=2 / 60"
else
    args="seconds=1.0"
fi
timeout "$BENCH_S" "$py" -c "from cloth_sim.bench.gpu import print_gpu_tables as t; t($args)" \
    2>&1 | tee -a "$OUT/bench.log"
echo "bench exit: ${PIPESTATUS[0]}" | tee -a "$OUT/bench.log"
