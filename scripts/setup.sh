#!/usr/bin/env bash
# One-time set-up on a fresh machine: a virtual environment in .venv with the CPU build of torch 2.13.0, then
# bboxtune with its test dependencies. Safe to re-run.
# torch comes first, so stable-baselines3's torch requirement is already met and no CUDA wheels are downloaded:
# torch==2.13.0+cpu from the configured package indexes (pip's own settings: a local wheel folder or a mirror
# that carries it); where they lack it, as PyPI does (its torch 2.13.0 for Linux is a CUDA build), torch==2.13.0
# from the PyTorch project's CPU wheel index ($TORCH_CPU_INDEX). Either way the set-up fails loudly if a CUDA
# build ends up installed. Sourcing this file only defines the functions (tests/scripts/test_setup.py).
set -euo pipefail

VENV_PYTHON=.venv/bin/python
TORCH_CPU_INDEX=https://download.pytorch.org/whl/cpu

install_torch() {  # the CPU build of torch 2.13.0: the configured indexes first, then the PyTorch CPU index
    if "$VENV_PYTHON" -m pip install -q "torch==2.13.0+cpu"; then
        return 0
    fi
    echo "setup.sh: torch==2.13.0+cpu is not in the configured package indexes;" \
         "installing torch==2.13.0 from the PyTorch CPU wheel index $TORCH_CPU_INDEX" >&2
    "$VENV_PYTHON" -m pip install -q --index-url "$TORCH_CPU_INDEX" "torch==2.13.0"
}

check_cpu_torch() {  # exits non-zero, naming the build, if the installed torch is a CUDA (or ROCm) build
    "$VENV_PYTHON" - <<'PY'
import sys

import torch

gpu = torch.version.cuda or getattr(torch.version, "hip", None)
if gpu:
    sys.exit(f"setup.sh: a GPU build of torch was installed ({torch.__version__}, {gpu}); bboxtune needs the CPU "
             "build: remove .venv and run scripts/setup.sh again (see README, Quick start)")
print(f"set-up done: torch {torch.__version__} (CPU build)")
PY
}

main() {
    cd "$(dirname "${BASH_SOURCE[0]}")/.."
    [ -x "$VENV_PYTHON" ] || python3 -m venv .venv
    install_torch
    "$VENV_PYTHON" -m pip install -q -e ".[dev]"  # the tests and the maintainers' checks (scripts/check.sh)
    check_cpu_torch
}

if [[ "${BASH_SOURCE[0]}" == "$0" ]]; then
    main "$@"
fi
