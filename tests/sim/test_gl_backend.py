"""A fresh process renders headless without MUJOCO_GL in its environment.

MuJoCo picks its GL backend once, at `import mujoco`; `pipeline.sim` imports it at module
level, so the EGL default must be set before that import. When it was set later (when LIBERO
was first made ready), every stage-2 episode of a run started without MUJOCO_GL was set aside
with "FatalError: gladLoadGL error".
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

SCRIPT = """
from pipeline.sim import build_env, tasks
from pipeline.sim.render import FrameRenderer
env = build_env(tasks(["libero_spatial"])[0])
env.reset_to_init(0)
r = FrameRenderer(env.env.sim.model._model, 32, "fast")
img = r.render(env.env.sim.data._data, "agentview")
print("frame", img.shape, int(img.max()))
"""


def test_fresh_process_renders_without_mujoco_gl():
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    r = subprocess.run([sys.executable, "-c", SCRIPT], cwd=REPO, env={**env, "PYTHONPATH": str(REPO)},
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "frame (32, 32, 3)" in r.stdout
    assert int(r.stdout.split()[-1]) > 0  # not a black frame
