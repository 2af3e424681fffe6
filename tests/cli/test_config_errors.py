"""Config mistakes end as a one-paragraph error with exit 2, never a traceback (issue 12)."""

from __future__ import annotations

import yaml

from tests.cli.test_tasks_command import _run


def test_an_unknown_task_name_exits_2_naming_file_and_key(tmp_path):
    cfg = tmp_path / "c.yaml"
    data = {"run": {"output_dir": str(tmp_path / "run")}, "tasks": {"suites": ["libero_goal"], "tasks": ["nope"]}}
    cfg.write_text(yaml.safe_dump(data))
    out = _run("stage1", "-c", str(cfg))
    assert out.returncode == 2, out.stderr
    assert "tasks.tasks" in out.stderr and "nope" in out.stderr and "c.yaml" in out.stderr
    assert "Traceback" not in out.stderr + out.stdout


def test_an_empty_config_exits_2_before_any_work(tmp_path):
    cfg = tmp_path / "empty.yaml"
    cfg.write_text("")
    out = _run("stage1", "-c", str(cfg))
    assert out.returncode == 2 and "empty config" in out.stderr
