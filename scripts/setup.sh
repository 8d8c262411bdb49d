#!/usr/bin/env bash
# One-time set-up on a fresh machine: a virtual environment in .venv with the CPU build of torch
# (torch==2.13.0+cpu is installed first, so stable-baselines3's torch requirement is already met and no
# CUDA wheels are downloaded), then bboxtune with its test dependencies. Safe to re-run.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q "torch==2.13.0+cpu"
.venv/bin/python -m pip install -q -e ".[test]"
.venv/bin/python - <<'PY'
import torch
assert torch.version.cuda is None, f"a CUDA build of torch was installed: {torch.__version__}"
print(f"set-up done: torch {torch.__version__} (CPU build)")
PY
