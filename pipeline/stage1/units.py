"""Stage 1 work units: one episode = (task, official init-state index), from the config.

Inputs: a validated `Config`. Outputs: `EpisodeUnit`s in registry order, and `Shard`s
(runs of units of one task) that the executor hands to workers.

Invariants:
- an episode's seed depends only on the run seed, the suite, the task and the init-state
  index (a hash), never on scheduling order or worker count, so reruns, resumes and
  different executors produce the same episodes;
- `unit_id` is unique within a run and safe as a file name (it names the done marker);
- every unit of a shard belongs to one task, so a worker builds one environment per shard.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

from pipeline.config import Config
from pipeline.layout import Stage1Layout, episode_key, unit_id
from pipeline.records import episode_id


def episode_seed(run_seed: int, suite: str, task: str, init_state: int) -> int:
    """A 31-bit seed derived from what identifies the episode, not from when it runs."""
    digest = hashlib.sha256(f"{run_seed}/{suite}/{task}/{init_state}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


@dataclass(frozen=True)
class EpisodeUnit:
    suite: str
    task: str
    task_index: int
    init_state: int
    seed: int
    policy: str  # policy name recorded with the episode

    @property
    def episode_id(self) -> str:
        return episode_id(self.policy, self.init_state, self.seed)

    @property
    def key(self) -> str:
        return episode_key(self.suite, self.task, self.episode_id)

    @property
    def unit_id(self) -> str:
        return unit_id(self.key)

    @property
    def rel_dir(self) -> str:
        """Episode folder relative to the run's stage1/ folder."""
        return Stage1Layout.episode_rel(self.key)


@dataclass(frozen=True)
class Shard:
    """Consecutive episodes of one task, run by one worker with one environment."""

    units: tuple[EpisodeUnit, ...]

    @property
    def task(self) -> tuple[str, str]:
        return self.units[0].suite, self.units[0].task


def policy_name(cfg: Config) -> str:
    return cfg.stage1.policy.name or cfg.stage1.policy.kind


def selected_tasks(cfg: Config):
    """The TaskSpecs the config selects, in registry order."""
    from pipeline.sim.registry import tasks

    names = cfg.tasks.tasks
    if names:
        # a name belongs to one suite: check it against all listed suites, then filter each
        known = {t.name for t in tasks(cfg.tasks.suites)}
        missing = [n for n in names if n not in known]
        if missing:
            raise cfg.error("tasks.tasks", f"unknown task name(s) {missing} in suites {cfg.tasks.suites}")
    out = []
    for suite in cfg.tasks.suites:
        chosen = [t for t in tasks([suite]) if not names or t.name in names]
        if cfg.tasks.max_tasks_per_suite is not None:
            chosen = chosen[: cfg.tasks.max_tasks_per_suite]
        out.extend(chosen)
    return out


def plan_units(cfg: Config, task_specs=None) -> list[EpisodeUnit]:
    """Every episode of the run, task by task, init states in config order."""
    specs = selected_tasks(cfg) if task_specs is None else task_specs
    name = policy_name(cfg)
    return [
        EpisodeUnit(t.suite, t.name, t.index, i, episode_seed(cfg.run.seed, t.suite, t.name, i), name)
        for t in specs
        for i in cfg.tasks.init_states
    ]


def make_shards(units: list[EpisodeUnit], workers: int) -> list[Shard]:
    """Group pending units by task; split a task only when there are too few tasks to keep
    every worker busy (each split costs one more environment build)."""
    by_task: dict[tuple[str, str], list[EpisodeUnit]] = {}
    for u in units:
        by_task.setdefault((u.suite, u.task), []).append(u)
    if not by_task:
        return []
    parts_per_task = math.ceil(workers / len(by_task))
    shards = []
    for group in by_task.values():
        n = min(parts_per_task, len(group))
        size = math.ceil(len(group) / n)
        shards.extend(Shard(tuple(group[i : i + size])) for i in range(0, len(group), size))
    # longest first, so the last shard to finish is a short one
    return sorted(shards, key=lambda s: -len(s.units))
