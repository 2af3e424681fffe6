"""The train/eval split (`pipeline.release.split`): seeded, stratified, stable when scenes are
added, redrawn by verify; its users (demos, eval, LeRobot splits) take their side. No simulator."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest

from pipeline.config import SplitConfig
from pipeline.eval.scenes import Scene, choose_split
from pipeline.release.lerobot_format import splits
from pipeline.release.manifest import ScenarioRow
from pipeline.release.recovery_demos import train_rows
from pipeline.release.split import apply, assign, check
from pipeline.release.verify import split_problems

SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10", "libero_90")


def _row(suite: str, i: int, level: str = "L2") -> ScenarioRow:
    return ScenarioRow(suite=suite, task=f"task_{i % 7}", instruction="do it", episode_id=f"scripted-i{i % 50:02d}-s{i}",
                       init_state=i % 50, step=100 + i, fail_time_s=1.0, fail_step=20, level=level,
                       category="grasp_failure", recovery_action="retry", policy="scripted", policy_kind="scripted",
                       seed=i, state_dim=92, bddl_path=f"b{i}.bddl", bddl_sha256="0", state_path=f"s{i}.npy",
                       state_sha256="0")


def _rows(n_per_suite: int, start: int = 0) -> list[ScenarioRow]:
    return [_row(s, i, ("L1", "L2", "L3", "L4")[i % 4]) for s in SUITES for i in range(start, start + n_per_suite)]


def test_same_rows_and_seed_give_the_same_split_and_another_seed_another():
    rows = _rows(40)
    assert assign(rows, SplitConfig(seed=3)) == assign(list(reversed(rows)), SplitConfig(seed=3))[::-1]
    assert assign(rows, SplitConfig(seed=3)) != assign(rows, SplitConfig(seed=4))


def test_the_share_holds_in_every_suite_and_the_reference_count_is_near():
    # the reference: 413 recovery scenes of 2,178, drawn uniformly over the five suites
    rows = _rows(436)  # 2,180 scenes
    sides = assign(rows, SplitConfig())
    assert 370 <= sum(s == "train" for s in sides) <= 460
    for suite in SUITES:
        part = [s for r, s in zip(rows, sides) if r.suite == suite]
        assert 0.13 <= sum(s == "train" for s in part) / len(part) <= 0.25, suite


def test_adding_scenes_leaves_every_existing_scene_on_its_side():
    old = _rows(30)
    new = old + _rows(30, start=30)
    cfg = SplitConfig(train_share=0.4)
    assert assign(new, cfg)[: len(old)] == assign(old, cfg)


def test_every_suite_of_two_or_more_scenes_gets_a_train_scene_unless_the_share_is_zero():
    rows = [_row("libero_goal", i, ("L1", "L2", "L3")[i % 3]) for i in range(3)]
    assert sum(s == "train" for s in assign(rows, SplitConfig(train_share=1e-9))) == 1
    assert set(assign(rows, SplitConfig(train_share=0.0))) == {"eval"}


def test_a_stratum_of_two_or_more_keeps_an_eval_scene_even_at_share_one():
    rows = [_row("libero_goal", 0), _row("libero_goal", 1), _row("libero_10", 2, "L3")]
    sides = assign(rows, SplitConfig(train_share=1.0))
    assert sorted(sides[:2]) == ["eval", "train"] and sides[2] == "train"  # a lone scene is not split


def test_verify_redraws_the_split_and_names_a_flipped_scene(tmp_path: Path):
    rows, info = apply(_rows(8), SplitConfig(seed=7, train_share=0.5))
    (tmp_path / "split.json").write_text(json.dumps(info.model_dump(mode="json")))
    assert split_problems(tmp_path, rows) == []
    flipped = list(rows)
    flipped[0] = rows[0].model_copy(update={"split": "eval" if rows[0].split == "train" else "train"})
    problems = split_problems(tmp_path, flipped)
    assert any("is " + str(flipped[0].split) in p and "put it in" in p for p in problems)
    assert any("counts differ" in p for p in problems)
    assert check(rows + rows[:1], info, "x")[0].endswith("is listed 2 times")
    (tmp_path / "split.json").unlink()
    assert "split.json: missing" in split_problems(tmp_path, rows)[0]
    assert split_problems(tmp_path, [r.model_copy(update={"split": None}) for r in rows]) == []  # pre-split release


def test_demos_take_the_train_scenes_and_eval_the_eval_scenes_by_default():
    rows, _ = apply(_rows(6), SplitConfig(train_share=0.5))
    train = train_rows(rows)
    assert train and all(r.split == "train" for r in train) and len(train) < len(rows)
    scenes = [Scene(r.suite, r.task, r.episode_id, r.step, Path(r.bddl_path), Path(r.state_path), split=str(r.split))
              for r in rows]
    chosen, note = choose_split(scenes, "eval")
    assert {s.split for s in chosen} == {"eval"} and len(chosen) == len(rows) - len(train)
    assert "held out" in note
    everything, note = choose_split(scenes, "all")
    assert len(everything) == len(rows) and "not held out" in note
    unsplit = [Scene(s.suite, s.task, s.episode_id, s.step, s.bddl_path, s.state_path) for s in scenes]
    assert choose_split(unsplit, "eval")[0] == unsplit


def test_lerobot_splits_are_the_index_ranges_of_each_side():
    assert splits([{"split": "train"}] * 2 + [{"split": "eval"}] * 3) == {"train": "0:2", "eval": "2:5"}
    assert splits([{}, {}]) == {"train": "0:2"}
    with pytest.raises(ValueError, match="contiguous"):
        splits([{"split": "train"}, {"split": "eval"}, {"split": "train"}])


def test_the_card_counts_libero_100_from_its_halves_and_each_scene_once_in_the_total():
    from pipeline.config import Config
    from pipeline.release.card import render_card

    rows, _ = apply(_rows(4), SplitConfig())  # 4 scenes per suite, one per level
    card = render_card(rows, Config(), {}, 2)
    assert "| *libero_100* | 2 | 2 | 2 | 2 | 8 |" in card
    assert "| **total** | 5 | 5 | 5 | 5 | 20 |" in card
    assert "16 evaluation" in card and "## Train / eval split" in card


def test_recover_eval_split_flag_overrides_the_config_and_refuses_other_values(tmp_path):
    import yaml
    from typer.testing import CliRunner

    from pipeline.cli import app

    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(tmp_path / "run")}}))
    shown = CliRunner().invoke(app, ["eval", "--config", str(cfg), "--split", "all", "--dry-run"])
    assert shown.exit_code == 0 and yaml.safe_load(shown.output)["eval"]["split"] == "all"
    bad = CliRunner().invoke(app, ["eval", "--config", str(cfg), "--split", "test"])
    assert bad.exit_code == 2
