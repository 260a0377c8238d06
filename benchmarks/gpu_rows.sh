#!/usr/bin/env bash
# The GPU rows of docs/performance.md, in one call on a machine with a GPU:
#
#     bash benchmarks/gpu_rows.sh OUT_DIR
#
# Uses that machine's own Python with JAX for CUDA (the repository on PYTHONPATH, no install);
# wheels in .whl/ (pyserial, which the package imports) are installed to /tmp/site first.
# Runs the moment pass at several chunk sizes, then the batch benchmark with the fastest chunk
# (peers in the same run: SciPy on the host's CPU, optimistix vmapped on the GPU), then the
# same batch benchmark on that machine's CPU as the baseline. Everything printed goes to
# OUT_DIR/log.txt; results to OUT_DIR/*_gpu.* and OUT_DIR/cpu/.
set -uo pipefail
out=${1:-/tmp/gpu_rows}
mkdir -p "$out/cpu"
exec > >(tee "$out/log.txt") 2>&1
if ls .whl/*.whl > /dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl || exit 1
    export PYTHONPATH=/tmp/site
fi
export PYTHONPATH=${PYTHONPATH:+$PYTHONPATH:}$PWD PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm,clocks.max.sm --format=csv
python3 -c "import jax, optimistix, equinox; print('jax', jax.__version__, jax.devices(), \
'optimistix', optimistix.__version__, 'equinox', equinox.__version__)"
date
timeout 120 python3 benchmarks/moment_pass.py --sensors 10000 --repeats 15 \
    --chunks 64 512 1024 4096 --out "$out"
best=$(python3 -c "import json; print(json.load(open('$out/moment_pass_gpu.json'))['best_chunk'])" \
    2> /dev/null || echo 1024)
date
timeout 270 python3 benchmarks/batch.py --sizes 1 1000 10000 100000 --peer-max 100 \
    --moment-chunk "$best" --out "$out"
date
JAX_PLATFORMS=cpu timeout 100 python3 benchmarks/batch.py --sizes 1000 --peer-max 100 \
    --out "$out/cpu"
date
