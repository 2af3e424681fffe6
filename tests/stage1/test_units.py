"""Work units: deterministic seeds and ids, task-affine shards."""

from __future__ import annotations

from pipeline.config import Config
from pipeline.sim.registry import TaskSpec
from pipeline.stage1.units import EpisodeUnit, episode_seed, make_shards, plan_units


def _spec(suite: str, name: str, index: int) -> TaskSpec:
    return TaskSpec(suite=suite, index=index, name=name, instruction=name, bddl_path="x.bddl", init_states_path="x")


def _cfg(**tasks) -> Config:
    return Config.model_validate({"run": {"seed": 7}, "tasks": {"init_states": [0, 1, 2], **tasks}})


def test_seed_depends_on_the_episode_not_on_the_order_it_runs_in():
    specs = [_spec("libero_spatial", "a", 0), _spec("libero_goal", "b", 0)]
    forward = {u.key: u.seed for u in plan_units(_cfg(), specs)}
    backward = {u.key: u.seed for u in plan_units(_cfg(init_states=[2, 1, 0]), specs[::-1])}
    assert forward == backward
    assert len(set(forward.values())) == 6


def test_seed_changes_with_run_seed_task_and_init_state():
    base = episode_seed(0, "libero_spatial", "a", 0)
    assert base == episode_seed(0, "libero_spatial", "a", 0)
    assert base != episode_seed(1, "libero_spatial", "a", 0)
    assert base != episode_seed(0, "libero_spatial", "b", 0)
    assert base != episode_seed(0, "libero_spatial", "a", 1)
    assert 0 <= base < 2**31


def test_unit_ids_are_unique_file_names_and_keys_follow_the_layout():
    units = plan_units(_cfg(), [_spec("libero_spatial", "a", 0), _spec("libero_goal", "a", 3)])
    assert len({u.unit_id for u in units}) == len(units)
    assert all("/" not in u.unit_id for u in units)
    u = units[0]
    assert u.key == f"libero_spatial/a/scripted-i00-s{u.seed}"
    assert u.rel_dir == f"episodes/{u.key}"


def _units(n_tasks: int, per_task: int) -> list[EpisodeUnit]:
    return [EpisodeUnit("s", f"t{t}", t, i, i, "p") for t in range(n_tasks) for i in range(per_task)]


def test_shards_keep_one_task_each_and_cover_every_unit_once():
    units = _units(5, 4)
    shards = make_shards(units, workers=2)
    assert len(shards) == 5  # enough tasks: one shard (one env build) per task
    assert all(len({u.task for u in s.units}) == 1 for s in shards)
    assert sorted(u.unit_id for s in shards for u in s.units) == sorted(u.unit_id for u in units)


def test_a_single_task_is_split_so_every_worker_has_work():
    shards = make_shards(_units(1, 5), workers=2)
    assert sorted(len(s.units) for s in shards) == [2, 3]
    assert make_shards([], workers=2) == []


def test_a_task_is_selected_by_name_when_two_suites_are_listed():
    from pipeline.stage1.units import selected_tasks

    cfg = _cfg(suites=["libero_goal", "libero_spatial"], tasks=["open_the_middle_drawer_of_the_cabinet"])
    chosen = selected_tasks(cfg)
    assert [(t.suite, t.name) for t in chosen] == [("libero_goal", "open_the_middle_drawer_of_the_cabinet")]


def test_an_unknown_task_name_is_a_config_error_naming_the_key(tmp_path):
    import pytest
    import yaml

    from pipeline.config import load_config
    from pipeline.errors import ConfigError
    from pipeline.stage1.units import selected_tasks

    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump({"tasks": {"suites": ["libero_goal"], "tasks": ["no_such_task"]}}))
    with pytest.raises(ConfigError, match=r"tasks\.tasks: unknown task name\(s\) \['no_such_task'\]") as e:
        selected_tasks(load_config(path))
    assert str(path) in str(e.value)
