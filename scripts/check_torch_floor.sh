#!/usr/bin/env bash
# The fast test suite on the oldest torch that pyproject.toml allows (`make torch-floor`): a
# throwaway venv with that torch, as the package registry serves it, and physgnn's other
# dependencies, then pytest on one thread from this checkout.
#   TORCH=<version>  another torch (default: the floor of "torch>=X" in pyproject.toml)
#   VENV=<folder>    where the venv goes (default /tmp/venv-torch-<version>); made anew and
#                    deleted after, unless KEEP=1
#   arguments        passed on to pytest (e.g. -x, tests/test_nn.py)
# The Linux wheel of torch < 2.5 on PyPI is the CUDA build: about 6 GB while it runs.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
floor="$(grep -oE '"torch>=[0-9.]+' "$ROOT/pyproject.toml" | cut -d= -f2)"
version="${TORCH:-$floor}"
venv="${VENV:-/tmp/venv-torch-$version}"
constraint="$(mktemp)"
cleanup() {
    rm -f "$constraint"
    if [ "${KEEP:-0}" != 1 ]; then rm -rf "$venv"; fi
}
trap cleanup EXIT
echo "torch==$version" >"$constraint"
rm -rf "$venv"
python3 -m venv "$venv"
"$venv/bin/pip" install -q --no-cache-dir --upgrade pip
"$venv/bin/pip" install -q --no-cache-dir -c "$constraint" "torch==$version"
"$venv/bin/pip" install -q --no-cache-dir -c "$constraint" -e "$ROOT[dev,launchers]"
"$venv/bin/python" -c "import torch; print('physgnn tests with torch', torch.__version__)"
cd "$ROOT"
OMP_NUM_THREADS=1 "$venv/bin/python" -m pytest -p no:cacheprovider "$@"
