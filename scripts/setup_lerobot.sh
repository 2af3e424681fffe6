#!/usr/bin/env bash
# The LeRobot environment, `.venv-lerobot/`: the real `lerobot==0.4.4` (policies, `lerobot-train`,
# the async-inference PolicyServer, LeRobotDataset and its v2.1 -> v3.0 converter) on the local
# CPU torch. It is its own environment because it needs numpy 2 (the main .venv pins numpy < 2
# for openpi-client); policies run in their own process anyway (pipeline/policies/lerobot_policy.py).
# lerobot pins torch < 2.11: installed with --no-deps after its pinned runtime dependencies
# (requirements/lerobot.txt), so no CUDA build is ever downloaded. Used by `policy.kind: lerobot`,
# the LeRobot tests and `scripts/lerobot_loop.py`; `scripts/setup.sh` calls this when
# WITH_LEROBOT=1 (`make setup-test`). Idempotent; ends by importing what the project uses.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
PY=${PYTHON:-python3.11}
VENV=${LEROBOT_VENV:-$ROOT/.venv-lerobot}
LEROBOT_VERSION=0.4.4

log() { printf '\033[1;34m[setup-lerobot]\033[0m %s\n' "$*"; }

[ -x "$VENV/bin/python" ] || { log "creating $VENV"; "$PY" -m venv "$VENV"; }
PIP=("$VENV/bin/python" -m pip install -q --disable-pip-version-check)
# an environment built by the older setup holds `lerobot-dataset` (the same code as module
# `ledataset`): one copy of LeRobot's dataset code is enough
"$VENV/bin/python" -m pip uninstall -q -y lerobot-dataset 2>/dev/null || true
# one resolve with torch pinned, so nothing can swap in a CUDA torch
"${PIP[@]}" -r "$ROOT/requirements/lerobot.txt"
"${PIP[@]}" --no-deps "lerobot==$LEROBOT_VERSION"
# the torchvision fix, loaded at interpreter start (a .pth line), so `lerobot-train` runs as is
SITE=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
cp "$ROOT/pipeline/lerobot_env/lerobot_compat.py" "$SITE/libero_recover_lerobot_compat.py"
echo "import libero_recover_lerobot_compat; libero_recover_lerobot_compat.install()" \
  > "$SITE/libero_recover_lerobot_compat.pth"
(cd "$(mktemp -d)" && "$VENV/bin/python" - <<'PY'
import torch
assert not torch.version.cuda, f"CUDA torch in the LeRobot env: {torch.__version__}"
import torchvision.io  # noqa: F401  (through the compat hook)
assert hasattr(torchvision.io, "VideoReader")
import lerobot
from lerobot.async_inference.policy_server import PolicyServer  # noqa: F401
from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: F401
from lerobot.policies.act.modeling_act import ACTPolicy  # noqa: F401
from lerobot.scripts.lerobot_train import train  # noqa: F401
from lerobot.processor.env_processor import LiberoProcessorStep  # noqa: F401
print("lerobot", lerobot.__version__, "torch", torch.__version__)
PY
)  # in a scratch folder: importing the PolicyServer makes a logs/ folder in the working directory
log "LeRobot environment ready: $VENV"
