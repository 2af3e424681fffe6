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


@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "configs").glob("*.yaml")) + [None])
def test_every_config_renders_both_review_cameras_at_256_px(name, tmp_path):
    cfg = load_config(ROOT / "configs" / name) if name else load_config(_write(tmp_path, {"run": {"seed": 0}}))
    assert cfg.stage1.video.cameras == ["agentview", "robot0_eye_in_hand"]
    assert cfg.stage1.video.resolution == 256


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


def test_lerobot_render_quality_defaults_to_liberos_look_and_refuses_others(tmp_path):
    assert load_config(_write(tmp_path, {"run": {"seed": 0}})).release.lerobot_render_quality == "standard"
    fast = load_config(_write(tmp_path, {"release": {"lerobot_render_quality": "fast"}}))
    assert fast.release.lerobot_render_quality == "fast"
    with pytest.raises(ConfigError, match=r"(?s)cfg\.yaml.*release\.lerobot_render_quality: .*'standard' or 'fast'"):
        load_config(_write(tmp_path, {"release": {"lerobot_render_quality": "draft"}}))


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


# -- issue 12: inputs the landed loader accepted silently


def test_an_empty_file_is_an_error_not_the_full_default_run(tmp_path):
    for text in ("", "# only a comment\n", "{}\n"):
        with pytest.raises(ConfigError, match="empty config") as e:
            load_config(_write(tmp_path, text))
        assert "cfg.yaml" in str(e.value)


@pytest.mark.parametrize(
    ("data", "key"),
    [
        ({"stage1": {"rollout": {"horizon": True}}}, "stage1.rollout.horizon"),
        ({"stage3": {"vlm": {"sampling": {"fps": False}}}}, "stage3.vlm.sampling.fps"),
        ({"tasks": {"max_tasks_per_suite": True}}, "tasks.max_tasks_per_suite"),
        ({"tasks": {"init_states": [0, True]}}, "tasks.init_states"),
        ({"stage1": {"rollout": {"stop_on_success": 1}}}, "stage1.rollout.stop_on_success"),
        ({"stage1": {"rollout": {"stop_on_success": "yes"}}}, "stage1.rollout.stop_on_success"),
    ],
)
def test_booleans_and_numbers_are_not_coerced_into_each_other(tmp_path, data, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")) as e:
        load_config(_write(tmp_path, data))
    assert "must be" in str(e.value)


def test_optional_booleans_still_accept_null_and_booleans(tmp_path):
    cfg = load_config(_write(tmp_path, {"stage2": {"vlm": {"openai": {"enable_thinking": None}}}}))
    assert cfg.stage2.vlm.openai.enable_thinking is None
    cfg = load_config(_write(tmp_path, {"stage2": {"vlm": {"openai": {"enable_thinking": False}}}}))
    assert cfg.stage2.vlm.openai.enable_thinking is False


@pytest.mark.parametrize(
    ("key", "value"),
    [("init_states", [0, 1, 1]), ("suites", ["libero_goal", "libero_goal"]), ("tasks", ["a", "a"])],
)
def test_repeated_selections_are_refused(tmp_path, key, value):
    with pytest.raises(ConfigError, match=rf"tasks\.{key}: .*repeated"):
        load_config(_write(tmp_path, {"tasks": {key: value}}))


def test_config_remembers_its_file_for_later_errors(tmp_path):
    p = _write(tmp_path, {"run": {"name": "x"}})
    err = load_config(p).error("tasks.tasks", "unknown task name(s) ['nope']")
    assert isinstance(err, ConfigError) and str(p) in str(err) and "tasks.tasks" in str(err)


@pytest.mark.parametrize("name, inits", [
    ("report", [42, 43]), ("report2", [44, 45]), ("report3", [46, 47]), ("report4", [48, 49]),
    ("report5", [40, 41]), ("report6", [38, 39]), ("report7", [36, 37]), ("report8", [34, 35]),
    ("report9", [32, 33]), ("report10", [30, 31]), ("report11", [28, 29]), ("report12", [26, 27]),
    ("report13", [24, 25]), ("report14", [22, 23]), ("report15", [20, 21]), ("report16", [18, 19]),
    ("report17", [16, 17]), ("report18", [14, 15]), ("report19", [12, 13]), ("report20", [10, 11]),
    ("report21", [8, 9])])
def test_the_report_configs_are_the_default_on_init_states_nobody_tunes_on(name, inits):
    """`extends`: a report run states only what differs (README, "Tuning protocol"); each
    round reports on init states no earlier report used."""
    default, report = load_config(ROOT / "configs/default.yaml"), load_config(ROOT / f"configs/{name}.yaml")
    assert report.tasks.init_states == inits and not set(report.tasks.init_states) & set(range(5))
    assert report.tasks.suites == default.tasks.suites and report.tasks.max_tasks_per_suite is None  # all 130 tasks
    assert report.stage1 == default.stage1 and report.release == default.release  # the noise is the default's
    assert report.run.name == name and report.run.seed == default.run.seed
    assert str(report.run.output_dir) == f"runs/{name}"


def test_tuning_configs_stay_on_init_states_0_to_4_and_reports_never_repeat():
    """The protocol's rule, on the configs in the repo: a tuning run never uses a report run's
    init states, and no two report runs share one."""
    tuning = sorted((ROOT / "configs/tuning").glob("*.yaml"))
    assert tuning, "configs/tuning/ holds the tuning runs' configs"
    for path in tuning:
        assert set(load_config(path).tasks.init_states) <= set(range(5)), path.name
    reports = [load_config(p).tasks.init_states for p in sorted((ROOT / "configs").glob("report*.yaml"))]
    used = [i for inits in reports for i in inits]
    # 5-41 is held out too: tuning stays on 0-4, so any of them is a fresh report pair
    assert len(reports) >= 2 and len(used) == len(set(used)) and min(used) >= 5


def test_extends_merges_section_by_section_and_names_a_bad_base(tmp_path):
    (tmp_path / "base.yaml").write_text(yaml.safe_dump({"run": {"name": "b", "seed": 4}, "stage1": {"rollout": {"horizon": 300}}}))
    child = _write(tmp_path, {"extends": "base.yaml", "run": {"name": "c"}})
    cfg = load_config(child)
    assert (cfg.run.name, cfg.run.seed, cfg.stage1.rollout.horizon) == ("c", 4, 300)
    _write(tmp_path, {"extends": "nowhere.yaml", "run": {"name": "c"}})
    with pytest.raises(ConfigError, match=r"nowhere\.yaml: no such config file \(`extends` of .*cfg\.yaml\)"):
        load_config(child)
    (tmp_path / "base.yaml").write_text(yaml.safe_dump({"extends": "cfg.yaml", "run": {"name": "b"}}))
    _write(tmp_path, {"extends": "base.yaml", "run": {"name": "c"}})
    with pytest.raises(ConfigError, match="a cycle"):
        load_config(child)
