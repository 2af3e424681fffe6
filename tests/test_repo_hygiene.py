"""Nothing that belongs to one machine is tracked: a tracked `.venv` symlink (a worktree's
link to the real venv) makes every merge of its branch replace the real environment with it."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).parents[1]
LOCAL = (".venv", "runs/", ".libero/")


@pytest.mark.skipif(shutil.which("git") is None or not (REPO / ".git").exists(), reason="not a git checkout")
def test_no_environment_or_run_output_is_tracked():
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    names = [n for n in tracked.decode().split("\0") if n]
    assert names, "git ls-files listed nothing"
    assert not [n for n in names if n.startswith(LOCAL)]
