"""Plan an evaluation: which trials to run, and how to shard them over workers.

Inputs: a validated `Config` and the scenes (`scenes.find_scenes`). Outputs: `Trial`s
(scene trials for every policy x chunk size x scene x gripper condition x trial index,
then RD reruns for every policy x scene x start state x rerun index at the first chunk
size) and `Shard`s of them.

Invariants: the plan is a pure function of the config and the scenes; unit ids are
unique; every shard holds trials of one scene BDDL (task), so a worker builds one
environment per shard; a task's trials are split over several shards only when there are
fewer tasks than workers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from pipeline.config import Config, PolicyConfig
from pipeline.eval.protocol import Trial
from pipeline.eval.rd import episode_dir, rd_starts
from pipeline.eval.scenes import Scene
from pipeline.layout import RunLayout


def policy_name(p: PolicyConfig) -> str:
    return p.name or p.kind


def default_scenes_dir(cfg: Config) -> Path:
    if cfg.eval.scenes_dir is not None:
        return Path(cfg.eval.scenes_dir)
    layout = RunLayout.of(cfg)
    return layout.release.root if layout.release.manifest.is_file() else layout.stage2.root


def stage1_dir(cfg: Config) -> Path:
    return Path(cfg.eval.stage1_dir) if cfg.eval.stage1_dir else RunLayout.of(cfg).stage1.root


def plan_trials(cfg: Config, scenes: list[Scene]) -> tuple[list[Trial], list[str]]:
    """All trials of the run, and problems (scenes without a usable source rollout for RD)."""
    e = cfg.eval
    common = dict(seed=cfg.run.seed, horizon=e.horizon, max_offset_m=e.max_offset_m,
                  gripper_settle_steps=e.gripper_settle_steps, temporal_context=e.temporal_context)
    trials: list[Trial] = []
    for p in e.policies:
        for chunk in e.chunk_sizes:
            for s in scenes:
                for g in e.gripper_conditions:
                    for t in range(e.trials_per_condition):
                        trials.append(Trial(scene=s, policy=policy_name(p), policy_kind=p.kind, gripper=g,
                                            trial=t, chunk_size=chunk, **common))
    problems: list[str] = []
    if e.rd:
        starts = {}
        for s in scenes:
            folder = episode_dir(stage1_dir(cfg), s.suite, s.task, s.episode_id)
            try:
                starts[s] = (folder, rd_starts(folder, s.step, e.rd_every_steps))
            except (FileNotFoundError, ValueError) as err:
                problems.append(f"RD skipped for {s.scene_id}: {err}")
        for p in e.policies:
            for s, (folder, st) in starts.items():
                for start in st:
                    for t in range(e.rd_trials):
                        trials.append(Trial(scene=s, policy=policy_name(p), policy_kind=p.kind,
                                            gripper=start.gripper, trial=t, chunk_size=e.chunk_sizes[0],
                                            mode="rd", rd_phase=start.phase, rd_start_step=start.start_step,
                                            rd_folder=folder, **common))
    ids = [t.unit_id for t in trials]
    if len(set(ids)) != len(ids):
        raise ValueError("eval plan has duplicate unit ids (duplicate policy names in eval.policies?)")
    return trials, problems


@dataclass(frozen=True)
class Shard:
    trials: tuple[Trial, ...]
    policies: tuple[PolicyConfig, ...]  # every policy config of the run (workers build by name)


def shard(trials: list[Trial], policies: list[PolicyConfig], workers: int) -> list[Shard]:
    groups: dict[tuple, list[Trial]] = {}
    for t in trials:
        groups.setdefault((t.scene.suite, t.scene.task), []).append(t)
    per_group = max(1, math.ceil(workers / max(1, len(groups))))
    out = []
    for group in groups.values():
        n = min(per_group, len(group))
        size = math.ceil(len(group) / n)
        out += [Shard(tuple(group[i : i + size]), tuple(policies)) for i in range(0, len(group), size)]
    return out
