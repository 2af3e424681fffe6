#!/usr/bin/env bash
# LeRobot's own dataset reader in a separate environment, `.venv-lerobot/`: it needs numpy 2
# (the main .venv pins numpy < 2 for openpi-client), and the `lerobot` package itself pins
# torch < 2.11, so we use `lerobot-dataset` (its LeRobotDataset, no torch pin) on the local
# CPU torch. Used by tests/release/test_lerobot_export.py; `scripts/setup.sh` calls this when
# WITH_LEROBOT=1 (`make setup-test`). Idempotent; ends by importing LeRobotDataset.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
PY=${PYTHON:-python3.11}
VENV=${LEROBOT_VENV:-$ROOT/.venv-lerobot}

log() { printf '\033[1;34m[setup-lerobot]\033[0m %s\n' "$*"; }

[ -x "$VENV/bin/python" ] || { log "creating $VENV"; "$PY" -m venv "$VENV"; }
# one resolve with torch pinned, so nothing can swap in a CUDA torch
"$VENV/bin/python" -m pip install -q --disable-pip-version-check -r "$ROOT/requirements/lerobot-reader.txt"
"$VENV/bin/python" - <<'PY'
import sys
sys.path.insert(0, "tests/release")
import lerobot_reader
lerobot_reader.load_torchvision()
from ledataset.datasets.lerobot_dataset import LeRobotDataset  # noqa: F401
import torch
assert not torch.version.cuda, f"CUDA torch in the reader env: {torch.__version__}"
PY
log "LeRobot reader ready: $VENV"
