"""The console script as a user runs it."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

RECOVER = shutil.which("recover", path=str(Path(sys.executable).parent)) or "recover"


def _run(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, COLUMNS="250")
    return subprocess.run([RECOVER, *args], capture_output=True, text=True, env=env, timeout=300, stdin=subprocess.DEVNULL)


def test_recover_tasks_lists_130_tasks_ten_per_small_suite_and_ninety():
    out = _run("tasks")
    assert out.returncode == 0, out.stderr
    assert "libero_spatial 10 + libero_object 10 + libero_goal 10 + libero_10 10 + libero_90 90 = 130" in out.stdout
    rows = [l for l in out.stdout.splitlines() if re.match(r"^│ libero_", l)]
    assert len(rows) == 130


def test_recover_tasks_filters_by_suite_and_rejects_unknown_suites():
    out = _run("tasks", "--suite", "libero_goal")
    assert out.returncode == 0 and "libero_goal 10 = 10" in out.stdout
    bad = _run("tasks", "--suite", "libero_100")
    assert bad.returncode == 2 and "libero_100" in bad.stderr


def test_a_stage_command_with_a_bad_config_exits_before_work_naming_the_key(tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("stage1:\n  rollout:\n    chunk_size: 3\n")
    out = _run("stage1", "--config", str(cfg))
    assert out.returncode == 2
    assert "stage1.rollout.chunk_size" in out.stderr and str(cfg) in out.stderr
    assert not (tmp_path / "runs").exists()
