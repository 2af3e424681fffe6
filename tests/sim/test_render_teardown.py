"""Processes that rendered exit cleanly: no EGL teardown tracebacks in any output (issue 12)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
TEARDOWN = ("Exception ignored", "GLContext.__del__", "EGLError")


def _env() -> dict:
    return dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"),
                PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))


@pytest.mark.sim
def test_a_process_exiting_with_an_open_renderer_prints_no_egl_traceback():
    # a worker's cached environment: still open, held by a module global, at interpreter exit
    code = textwrap.dedent("""
        from pipeline.sim import SimEnv
        from pipeline.sim.registry import tasks
        ENV = SimEnv(tasks(["libero_spatial"])[0])
        ENV.reset_to_init(0)
        assert ENV.render("agentview", 64, "fast").shape == (64, 64, 3)
        print("rendered")
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_env(), timeout=300)
    assert out.returncode == 0 and "rendered" in out.stdout, out.stderr[-3000:]
    assert not [m for m in TEARDOWN if m in out.stderr + out.stdout], out.stderr[-3000:]


@pytest.mark.sim
def test_a_real_stage_with_rendering_workers_prints_no_egl_traceback(tmp_path):
    cfg = {
        "run": {"name": "teardown", "output_dir": str(tmp_path / "run")},
        "tasks": {"suites": ["libero_spatial"], "max_tasks_per_suite": 1, "init_states": [0, 1]},
        "executor": {"kind": "local", "workers": 2},
        "stage1": {"rollout": {"horizon": 24}, "video": {"resolution": 64, "render": "all", "quality": "fast"}},
    }
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(cfg))
    recover = Path(sys.executable).parent / "recover"
    out = subprocess.run([str(recover), "stage1", "-c", str(path)], capture_output=True, text=True, env=_env(),
                         timeout=600, stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "2/2 episodes" in out.stdout
    assert not [m for m in TEARDOWN if m in out.stderr + out.stdout], out.stderr[-3000:]
