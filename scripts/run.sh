#!/usr/bin/env bash
# latentrl's two Quickstart commands, and the set-up they share.
#
#   bash scripts/run.sh quickstart   # set up .venv, then train + evaluate a policy on the embedded default model
#   bash scripts/run.sh test         # set up .venv, then run the test suite
#   bash scripts/run.sh setup        # only create/refresh .venv
#
# torch: a torch that the environment already has (e.g. a CUDA build you installed) is kept as it
# is. Otherwise the CPU build is installed first and pinned (torch==2.13.0 from PyTorch's CPU index):
# a bare `torch` requirement would pull a multi-GB CUDA build. The package itself asks for a range
# (torch>=2.4). GPU users: create the venv, install the CUDA build of torch into it
# (https://pytorch.org/get-started/locally/), then run this script; LATENTRL_TORCH and
# LATENTRL_TORCH_INDEX change what is installed when no torch is there.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
VENV=${LATENTRL_VENV:-.venv}
TORCH_SPEC=${LATENTRL_TORCH:-torch==2.13.0}
TORCH_INDEX=${LATENTRL_TORCH_INDEX:-https://download.pytorch.org/whl/cpu}

setup() {
    if [ ! -x "$VENV/bin/python" ]; then
        echo "[latentrl] creating virtual environment $VENV"
        "$PYTHON" -m venv "$VENV"
    fi
    if have=$("$VENV/bin/python" -c "import torch; print(torch.__version__, 'CUDA' if torch.version.cuda else 'CPU')" \
            2>/dev/null); then
        echo "[latentrl] keeping the installed torch $have"
    else
        echo "[latentrl] no torch in $VENV: installing $TORCH_SPEC, CPU build, from $TORCH_INDEX"
        if ! "$VENV/bin/python" -m pip install -q --retries 1 --timeout 15 "$TORCH_SPEC" --index-url "$TORCH_INDEX" \
                >"$VENV/torch-install.log" 2>&1; then
            echo "[latentrl] $TORCH_INDEX unreachable: installing $TORCH_SPEC from pip's configured index" \
                 "(on Linux PyPI's build is the CUDA one, a few GB; a local wheel folder may hold the CPU build)"
            "$VENV/bin/python" -m pip install -q "$TORCH_SPEC"
        fi
    fi
    echo "[latentrl] installing latentrl (editable) with numpy, gymnasium, stable-baselines3, tensorboard,"
    echo "[latentrl] pyyaml, omegaconf, tqdm, matplotlib, scipy and the test tools (.[dev]); torch is left as it is"
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
        # two worker processes by default (the CI machine's 2 cores); LATENTRL_TEST_WORKERS=0 runs in this process
        "$VENV/bin/python" -m pytest -q -n "${LATENTRL_TEST_WORKERS:-2}" "$@"
        ;;
    *)
        echo "usage: bash scripts/run.sh {quickstart|test|setup} [extra args]" >&2
        exit 2
        ;;
esac
