#!/usr/bin/env bash
# latentrl's two Quickstart commands, and the set-up they share.
#
#   bash scripts/run.sh quickstart   # set up .venv, then train + evaluate a policy on the embedded default model
#   bash scripts/run.sh test         # set up .venv, then run the test suite
#   bash scripts/run.sh setup        # only create/refresh .venv
#
# The CPU build of torch is installed first and pinned (torch==2.13.0): a bare `torch`
# requirement would pull a multi-GB CUDA build. The package itself asks for a range (torch>=2.3).
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
VENV=${LATENTRL_VENV:-.venv}
TORCH_SPEC=${LATENTRL_TORCH:-torch==2.13.0}

setup() {
    if [ ! -x "$VENV/bin/python" ]; then
        echo "[latentrl] creating virtual environment $VENV"
        "$PYTHON" -m venv "$VENV"
    fi
    if ! "$VENV/bin/python" -c "import torch" >/dev/null 2>&1; then
        echo "[latentrl] installing $TORCH_SPEC (CPU build) first"
        "$VENV/bin/python" -m pip install -q "$TORCH_SPEC"
    fi
    echo "[latentrl] installing latentrl and its dependencies"
    if ! "$VENV/bin/python" -m pip install -q -e ".[dev]" >"$VENV/pip-install.log" 2>&1; then
        grep -v "^WARNING: Location" "$VENV/pip-install.log" >&2
        exit 1
    fi
    "$VENV/bin/python" -c "import latentrl" || { echo "[latentrl] installation failed" >&2; exit 1; }
}

case "${1:-}" in
    setup)
        setup
        ;;
    quickstart)
        setup
        shift
        "$VENV/bin/latentrl" quickstart "$@"
        ;;
    test)
        setup
        shift
        "$VENV/bin/python" -m ruff check latentrl tests
        "$VENV/bin/python" -m pytest -q "$@"
        ;;
    *)
        echo "usage: bash scripts/run.sh {quickstart|test|setup} [extra args]" >&2
        exit 2
        ;;
esac
