from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from pipeline.config import load_config, save_resolved
from pipeline.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def _write(tmp_path: Path, data) -> Path:
    p = tmp_path / "cfg.yaml"
    p.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return p


def test_default_config_holds_the_reference_settings():
    cfg = load_config(ROOT / "configs/default.yaml")
    assert cfg.stage1.rollout.horizon == 520
    assert cfg.stage1.rollout.control_hz == 20
    assert cfg.stage1.rollout.chunk_size == 8
    assert len(cfg.tasks.suites) == 5 and cfg.tasks.max_tasks_per_suite is None
    assert cfg.tasks.init_states == list(range(50))


def test_smoke_config_is_small():
    cfg = load_config(ROOT / "configs/smoke.yaml")
    assert cfg.tasks.max_tasks_per_suite is not None
    assert len(cfg.tasks.init_states) <= 5
    assert cfg.stage1.rollout.horizon < 520


def test_unknown_key_fails_naming_the_file_and_dotted_key(tmp_path):
    p = _write(tmp_path, {"stage1": {"rollout": {"horizn": 10}}})
    with pytest.raises(ConfigError) as e:
        load_config(p)
    msg = str(e.value)
    assert str(p) in msg and "stage1.rollout.horizn" in msg and "unknown key" in msg


def test_bad_value_fails_naming_the_key_and_the_reason(tmp_path):
    p = _write(tmp_path, {"stage1": {"rollout": {"chunk_size": 64}}})
    with pytest.raises(ConfigError, match=r"stage1\.rollout\.chunk_size: .*less than or equal to 32"):
        load_config(p)


def test_unknown_suite_and_bad_fps_are_rejected(tmp_path):
    with pytest.raises(ConfigError, match=r"tasks\.suites: .*libero_100"):
        load_config(_write(tmp_path, {"tasks": {"suites": ["libero_100"]}}))
    with pytest.raises(ConfigError, match=r"stage1\.video\.fps: .*divide"):
        load_config(_write(tmp_path, {"stage1": {"video": {"fps": 3}}}))


def test_missing_file_and_broken_yaml_are_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(_write(tmp_path, "run: [unclosed"))
    with pytest.raises(ConfigError, match="top level must be a mapping"):
        load_config(_write(tmp_path, "- a\n- b\n"))


def test_resolved_config_round_trips(tmp_path):
    cfg = load_config(ROOT / "configs/smoke.yaml", overrides={"run.seed": 7})
    assert cfg.run.seed == 7
    path = save_resolved(cfg, tmp_path)
    assert load_config(path) == cfg
