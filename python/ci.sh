#!/usr/bin/env bash
# Builds the Python package into a fresh virtual environment, the way a user
# installs it (`pip install ./python`: maturin and protobuf from the package
# index, no C++ toolchain, no protoc), then runs its pytest suite.
# Called by .ci/run after the Rust tests; run it by hand from anywhere.
# Environment: PYTHON (default python3), DCCL_PY_VENV (default: a new
# temporary directory, removed at exit).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

python=${PYTHON:-python3}
if ! command -v "$python" >/dev/null; then
    echo "python/ci.sh: $python not found: the Python package needs CPython 3.9 or later" >&2
    exit 1
fi
if ! "$python" -c 'import sys; sys.exit(sys.version_info < (3, 9))'; then
    echo "python/ci.sh: $("$python" --version 2>&1) is older than 3.9" >&2
    exit 1
fi

# `venv` with pip: on Debian's Python it is the python3-venv package.
if ! "$python" -c 'import venv, ensurepip' 2>/dev/null; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "python/ci.sh: installing python3-venv"
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv >/dev/null
    else
        echo "python/ci.sh: $python has no venv/ensurepip module (install python3-venv)" >&2
        exit 1
    fi
fi

if [ -n "${DCCL_PY_VENV:-}" ]; then
    venv=$DCCL_PY_VENV
    rm -rf "$venv"
else
    venv=$(mktemp -d -t dccl-py-venv.XXXXXX)
    trap 'rm -rf "$venv"' EXIT
fi
"$python" -m venv "$venv"
pip() { "$venv/bin/python" -m pip --disable-pip-version-check "$@"; }

echo "python/ci.sh: pip install ./python into a fresh virtual environment ($("$python" --version 2>&1))"
start=$(date +%s)
pip install -q ./python
echo "python/ci.sh: installed in $(( $(date +%s) - start )) s (build included)"
# Test-only tools: pytest, and grpcio-tools for a protoc-generated _pb2 module.
pip install -q "pytest>=7" grpcio-tools

# From the workspace root, so that `import dccl` is the installed package.
set +e
"$venv/bin/pytest" -q -rs -p no:cacheprovider python/tests
status=$?
set -e
case $status in
    0) echo "python/ci.sh: Python tests passed" ;;
    5) echo "python/ci.sh: pytest collected no tests" >&2; exit 1 ;;
    *) echo "python/ci.sh: Python tests failed (pytest exit $status)" >&2; exit "$status" ;;
esac
