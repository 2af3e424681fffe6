"""Plan an evaluation: which trials to run.

Inputs: a validated `Config` and the scenes (`scenes.find_scenes`). Outputs: `Trial`s
(scene trials for every policy x chunk size x scene x gripper condition x trial index,
then official-init-state trials for every policy x task x `official_trials`, then RD reruns
for every policy x scene x start state x rerun index, both at the first chunk size); the eval Stage (stage.py) shards them by task.

Invariants: the plan is a pure function of the config and the scenes; unit ids are
unique.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.config import Config, EvalConfig, PolicyConfig
from pipeline.eval.protocol import Trial
from pipeline.eval.rd import episode_dir, rd_starts, stage2_phases
from pipeline.eval.scenes import Scene
from pipeline.layout import RunLayout


def policy_name(p: PolicyConfig) -> str:
    return p.name or p.kind


def context_of(p: PolicyConfig, e: EvalConfig) -> str:
    """The temporal context a policy is evaluated with: its own, else `eval.temporal_context`."""
    return p.temporal_context or e.temporal_context


def default_scenes_dir(cfg: Config) -> Path:
    if cfg.eval.scenes_dir is not None:
        return Path(cfg.eval.scenes_dir)
    layout = RunLayout.of(cfg)
    return layout.release.root if layout.release.manifest.is_file() else layout.stage2.root


def stage1_dir(cfg: Config) -> Path:
    return Path(cfg.eval.stage1_dir) if cfg.eval.stage1_dir else RunLayout.of(cfg).stage1.root


def stage2_dir(stage1: Path) -> Path:
    """Stage 2 beside the stage-1 folder the RD reruns come from: its phases label them."""
    return RunLayout(Path(stage1).parent).stage2.root


def source_stage1(cfg: Config, s: Scene) -> Path:
    """The stage-1 folder holding a scene's source rollout: this run's (or `eval.stage1_dir`),
    else that of the `release.merge_runs` run it came from; the first one if none has it."""
    candidates = [stage1_dir(cfg)] + [RunLayout(Path(r)).stage1.root for r in cfg.release.merge_runs]
    return next((c for c in candidates if episode_dir(c, s.suite, s.task, s.episode_id).is_dir()), candidates[0])


def plan_trials(cfg: Config, scenes: list[Scene]) -> tuple[list[Trial], list[str]]:
    """All trials of the run, and problems (scenes without a usable source rollout for RD)."""
    e = cfg.eval
    common = dict(seed=cfg.run.seed, horizon=e.horizon, max_offset_m=e.max_offset_m,
                  gripper_settle_steps=e.gripper_settle_steps)
    trials: list[Trial] = []
    context = {policy_name(p): context_of(p, e) for p in e.policies}
    for p in e.policies:
        for chunk in e.chunk_sizes:
            for s in scenes:
                for g in e.gripper_conditions:
                    for t in range(e.trials_per_condition):
                        trials.append(Trial(scene=s, policy=policy_name(p), policy_kind=p.kind, gripper=g,
                                            trial=t, chunk_size=chunk,
                                            temporal_context=context[policy_name(p)], **common))
    # standard LIBERO success: each task's official init states, on its first scene's
    # environment (the scene's BDDL is the task's, so its model restores them)
    first_scene = {}
    for s in scenes:
        first_scene.setdefault((s.suite, s.task), s)
    for p in e.policies:
        for s in first_scene.values():
            for t in range(e.official_trials):
                trials.append(Trial(scene=s, policy=policy_name(p), policy_kind=p.kind, gripper="open", trial=t,
                                    chunk_size=e.chunk_sizes[0], mode="official",
                                    temporal_context=context[policy_name(p)], **common))
    problems: list[str] = []
    if e.rd:
        starts = {}
        for s in scenes:
            stage1 = source_stage1(cfg, s)
            folder = episode_dir(stage1, s.suite, s.task, s.episode_id)
            try:
                phases = stage2_phases(stage2_dir(stage1), s.source_key)
                # the onset: a released scene's reviewed one; a stage-2 scene's, its phases'
                onset = s.step if phases is None else s.fail_step if s.fail_step is not None else phases.during[0]
                starts[s] = (folder, rd_starts(folder, onset, e.rd_every_steps, phases))
            except (FileNotFoundError, ValueError) as err:
                problems.append(f"RD skipped for {s.scene_id}: {err}")
                continue
            if phases is None:
                problems.append(f"RD of {s.scene_id}: no stage-2 phases (localization) in {stage2_dir(stage1)}: "
                                f"starts labelled pre / post at the scene step only")
        for p in e.policies:
            for s, (folder, st) in starts.items():
                for start in st:
                    for t in range(e.rd_trials):
                        trials.append(Trial(scene=s, policy=policy_name(p), policy_kind=p.kind,
                                            gripper=start.gripper, trial=t, chunk_size=e.chunk_sizes[0],
                                            mode="rd", rd_phase=start.phase, rd_start_step=start.start_step,
                                            rd_folder=folder, temporal_context=context[policy_name(p)], **common))
    ids = [t.unit_id for t in trials]
    if len(set(ids)) != len(ids):
        raise ValueError("eval plan has duplicate unit ids (duplicate policy names in eval.policies?)")
    return trials, problems
