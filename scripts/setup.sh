#!/usr/bin/env bash
# One idempotent setup for a fresh machine: system libs for headless EGL rendering,
# a .venv with the CPU LIBERO stack, LIBERO's assets, and the project itself.
# Re-running is cheap: pip skips what is satisfied; a stamp skips the apt step.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
PY=${PYTHON:-python3.11}
VENV=${VENV:-$ROOT/.venv}

log() { printf '\033[1;34m[setup]\033[0m %s\n' "$*"; }

# --- system packages (EGL/Mesa for offscreen MuJoCo, ffmpeg libs come with PyAV) ---
need_apt=()
ldconfig -p | grep -q 'libEGL.so.1' || need_apt+=(libegl1)
ldconfig -p | grep -q 'libGL.so.1' || need_apt+=(libgl1)
ls /usr/share/glvnd/egl_vendor.d/*mesa* >/dev/null 2>&1 || need_apt+=(libegl-mesa0 libgl1-mesa-dri)
if [ "${WITH_BROWSER:-0}" = 1 ] && ! command -v chromium >/dev/null; then need_apt+=(chromium); fi
# the review tests start a throwaway PostgreSQL server (tests/pg_cluster.py) from Debian's binaries
if [ "${WITH_POSTGRES:-0}" = 1 ] && ! ls /usr/lib/postgresql/*/bin/postgres >/dev/null 2>&1; then need_apt+=(postgresql); fi
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    log "installing system packages: ${need_apt[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >/dev/null
  else
    echo "setup: missing system packages ${need_apt[*]} (EGL for headless rendering; chromium/postgresql for the tests); install them with your package manager" >&2
    exit 1
  fi
fi

# --- virtual environment ---
[ -x "$VENV/bin/python" ] || { log "creating $VENV"; "$PY" -m venv "$VENV"; }
PIP="$VENV/bin/python -m pip install -q --disable-pip-version-check"
# torch first, pinned: any other spec pulls a multi-GB CUDA build.
$PIP "torch==2.13.0"
# LIBERO's own pins drag in wandb/robomimic; install it bare and list what it imports.
$PIP --no-deps "libero==0.1.1"
$PIP -r "$ROOT/requirements/sim.txt"
$PIP -e "$ROOT[dev,vlm]"

# --- LIBERO config + assets (never let `import libero.libero` call input()) ---
"$VENV/bin/python" -c "from pipeline.sim.libero_setup import main; main()"

# --- the LeRobot environment (lerobot 0.4.4 on CPU torch; numpy 2): a separate .venv-lerobot ---
if [ "${WITH_LEROBOT:-0}" = 1 ]; then bash "$ROOT/scripts/setup_lerobot.sh"; fi
log "done. Activate with: source .venv/bin/activate"
