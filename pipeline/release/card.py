"""The dataset card: `README.md` (tables and provenance) and a stacked-bar PNG.

Inputs: the manifest rows, the resolved config, the package versions. Outputs: markdown
text and `figures/scenes_by_suite_level.png` (the object-positions figure beside it is
`pipeline.release.positions`'s). Invariant: deterministic bytes for the same
inputs (no dates, no absolute paths: output folders and database URLs are redacted from
the config; PNG written without software/date metadata).
"""

from __future__ import annotations

import sys
from collections import Counter
from importlib import metadata
from pathlib import Path

import yaml

from pipeline.atomic import write_with
from pipeline.config import Config, reported_suites
from pipeline.records import Category, Level
from pipeline.release.manifest import ScenarioRow
from pipeline.release.positions import FIGURE as POSITIONS_FIGURE

FIGURE = "figures/scenes_by_suite_level.png"
LEVELS = [lv.value for lv in Level]
CATEGORIES = [c.value for c in Category]


def versions() -> dict[str, str]:
    out = {"python": ".".join(map(str, sys.version_info[:3]))}
    for pkg in ("libero", "robosuite", "mujoco", "bddl", "libero-recover"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def portable_config(cfg: Config) -> dict:
    """The config as saved in the card: paths that depend on where it ran are redacted."""
    d = cfg.model_dump(mode="json")
    d["run"]["output_dir"] = "<run>"
    d["release"]["output_dir"] = None
    # located elsewhere and renamed by `recover reproduce`: counted, not named (the generator
    # table says what each contributed)
    d["release"]["merge_runs"] = [f"<merged run {i + 1}>" for i in range(len(d["release"].get("merge_runs", [])))]
    for stage in ("stage3",):
        if d[stage].get("db_url"):
            d[stage]["db_url"] = "<redacted>"
    return d


def _table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def write_figure(rows: list[ScenarioRow], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = reported_suites({r.suite for r in rows}) or [("(none)", ())]
    suites = [name for name, _ in groups]  # LIBERO-100 as its own bar, from its halves' scenes
    by_sl = Counter((r.suite, r.level) for r in rows)
    counts = {(name, lv): sum(by_sl[(m, lv)] for m in members) for name, members in groups for lv in LEVELS}
    fig, ax = plt.subplots(figsize=(1.6 + 1.3 * len(suites), 3.6), dpi=100)
    bottom = [0] * len(suites)
    for level in LEVELS:
        vals = [counts[(s, level)] for s in suites]
        ax.bar(suites, vals, bottom=bottom, label=level)
        bottom = [b + v for b, v in zip(bottom, vals)]
    ax.set_ylabel("scenes")
    ax.set_title("Scenes by suite and recovery level")
    ax.legend(title="level", fontsize=8)
    ax.tick_params(axis="x", labelsize=8)
    fig.tight_layout()
    write_with(path, lambda p: fig.savefig(p, format="png", metadata={"Software": None}))
    plt.close(fig)


EXPERT_TEXT = {
    "recovery": "The recovery expert (zero noise: it first restores the plan's preconditions, then runs\n"
                "the task, and gives up with a reason when it cannot)",
    "plain": "The plain scripted expert (zero noise, the stage-1 generator without its noise)",
}


def _uncertified(rows: list[ScenarioRow]) -> str:
    """Why scenes are not certified: counts per reason, then each scene."""
    bad = [r for r in rows if r.certified is False]
    if not bad:
        return ""
    reasons = Counter(r.certify_reason or "unknown" for r in bad)
    scenes = [[f"`{r.suite}/{r.task}/{r.episode_id}@{r.step}`", r.level, r.category, r.certify_reason or "unknown"]
              for r in bad]
    return ("\n" + _table(["reason", "scenes"], [[k, n] for k, n in sorted(reasons.items())]) + "\n\n"
            + _table(["scene", "level", "category", "reason"], scenes) + "\n")


def restore_source() -> str:
    """The one restore's source (`pipeline.sim.restore.restore`), quoted whole by the card."""
    import inspect

    from pipeline.sim.restore import restore

    return inspect.getsource(restore).rstrip()


def restore_section() -> str:
    """How to restore a scene and replay what was recorded from it, in plain LIBERO."""
    return f"""Restore a scene in plain LIBERO with this function, the one the project itself uses
(`pipeline/sim/restore.py`: stage 1, `recover eval`, certification, the recovery demos, the
LeRobot export and `recover verify --replay` all start from it). LIBERO places fixtures
(cabinets, stoves, racks) by sampling from the global `np.random` at every reset, and fixture
poses are not in the flattened state: these scenes were recorded with that sampler seeded
with 0. The lines after `set_init_state` set what the flattened state leaves out: the arm
controller's cached pose (it would otherwise anchor the first action to the pose before the
restore), the Panda gripper's command ramp and MuJoCo's solver warm start.

```python
import numpy as np
from libero.libero.envs import OffScreenRenderEnv  # or ControlEnv (no cameras)


{restore_source()}


env = OffScreenRenderEnv(bddl_file_name="step_NNNN.bddl")  # the scene's own BDDL
restore(env, np.load("step_NNNN_sim_state.npy"), hold_grasp=True)
```

Actions are stored at the precision they were executed with (the simulator stepped float64
actions; rounding them before stepping would have changed the rollouts): each episode folder
(stage-1 rollouts, recovery demos) has `actions.npy`, (steps, 7) float64, and the LeRobot
datasets have `action_float64` beside the float32 `action`. The float32 `action` (also in
`steps.parquet`) is the same values rounded: train on it, but replay the float64 ones; the
rounded ones drift from the recorded states after the first step. A recovery demo
replays from its scene: `restore(env, scene_state, hold_grasp=True)`, then
`env.step(a)` for each row of `actions.npy`; the states equal the demo's `states.npy` bit
for bit and `env.check_success()` first holds at its last step. `recover demos` keeps
a demo only if it replays so, and `recover verify --replay` checks every demo again. A
stage-1 rollout replays from its LIBERO init state: `restore(env, init_states[i])`, then
`settle_steps` actions `[0, 0, 0, 0, 0, 0, -1]`, then `actions.npy` (the LeRobot export
checks this for every exported rollout and pre-failure history)."""


def _suite_level_rows(rows: list[ScenarioRow]) -> list[list]:
    """Scenes per suite (LIBERO-100 beside its halves, counted from scenes) and level, and a total."""
    by_sl = Counter((r.suite, r.level) for r in rows)
    out = []
    for name, members in reported_suites({r.suite for r in rows}):
        counts = [sum(by_sl[(m, lv)] for m in members) for lv in LEVELS]
        out.append([name if members == (name,) else f"*{name}*", *counts, sum(counts)])
    out.append(["**total**", *(sum(by_sl[(s, lv)] for s in {r.suite for r in rows}) for lv in LEVELS), len(rows)])
    return out


def _split_section(rows: list[ScenarioRow], cfg: Config) -> str:
    sp = cfg.release.split
    blocks = []
    for side in ("train", "eval"):
        part = [r for r in rows if r.split == side]
        blocks.append(f"**{side}** ({len(part)} scenes)\n\n" + _table(["suite", *LEVELS, "total"], _suite_level_rows(part)))
    return (f"Recovery demonstrations (`recover demos`) are recorded on the **train** scenes only, and\n"
            f"`recover eval` scores policies on the **eval** scenes by default, so a policy fine-tuned on\n"
            f"the demonstrations is not scored on its own training scenes. A scene is train when\n"
            f"SHA-256(\"split/<seed>/<scene id>\") read as a number in [0, 1) is below the train share\n"
            f"(seed {sp.seed}, train share {sp.train_share}): uniform within every suite x level, the same for\n"
            f"the same seed, and unchanged for existing scenes when scenes are added; a suite with two or\n"
            f"more scenes always gets one train scene, and a suite x level with two or more scenes keeps\n"
            f"one eval scene. The column `split` of `scenarios.parquet`\n"
            f"and `split.json` record it; `recover verify` redraws it.\n\n" + "\n\n".join(blocks))


def _generators(rows: list[ScenarioRow]) -> str:
    """Scenes per generator (`kind:name@params hash`) and split: a merged release has several."""
    gens = sorted({r.generator or f"{r.policy_kind}:{r.policy}" for r in rows})
    body = []
    for g in gens:
        part = [r for r in rows if (r.generator or f"{r.policy_kind}:{r.policy}") == g]
        body.append([f"`{g}`", len(part), sum(r.split == "train" for r in part), sum(r.split == "eval" for r in part)])
    return (_table(["generator (kind:name@params hash)", "scenes", "train", "eval"], body or [["(none)", 0, 0, 0]])
            + "\n\nThe hash is of the generator's recorded parameters (`policy_params` in the source run's"
            "\n`stage1/episodes.parquet`: noise levels, server, checkpoint); `release.merge_runs` merges\nthe "
            "scenes of several runs (generators or seeds) into one release.")


def render_card(rows: list[ScenarioRow], cfg: Config, prompt_hashes: dict[str, list[str]], reviewers: int) -> str:
    by_cat = Counter(r.category for r in rows)
    certified = sum(r.certified is True for r in rows)
    attempted = sum(r.certified is not None for r in rows)
    level_rows = _suite_level_rows(rows)
    cat_rows = [[c, by_cat[c]] for c in CATEGORIES if by_cat[c]] or [["(none)", 0]]
    hashes = "\n".join(f"- {k}: {', '.join(f'`{h}`' for h in v) or '(none)'}" for k, v in prompt_hashes.items())
    vers = "\n".join(f"- {k}: {v}" for k, v in versions().items())
    return f"""# libero-recover scenario set

Restorable failure scenes mined from real executions of robot policies in LIBERO, each
labelled by people with a recovery level, a failure category and a recovery action.
Every scene is a pair: a BDDL problem file (`step_<NNNN>.bddl`) and the flattened MuJoCo
state (`step_<NNNN>_sim_state.npy`: time, qpos, qvel) at the failure, with the episode's
pre-failure history beside it. `scenarios.parquet` lists every scene with its labels and
the SHA-256 of each file; `recover verify <this folder>` checks a copy.

## Restoring a scene

{restore_section()}
## Scenes per suite and recovery level ({len(rows)} scenes)

{_table(["suite", *LEVELS, "total"], level_rows)}

*libero_100* is LIBERO-10 and LIBERO-90 together (the reference's LIBERO-100), counted from
their scenes: with libero_spatial, libero_object and libero_goal it makes the 16 evaluation
dimensions of the reference (4 suites x 4 levels). The total counts each scene once.

![scenes by suite and level]({FIGURE})

Where the scenes put the objects, against LIBERO's official init states of the same tasks
(x/y on the table of every movable object; grey: the official init states, red: the scenes):

![object positions: scenes vs official init states]({POSITIONS_FIGURE})

## Train / eval split

{_split_section(rows, cfg)}

## Scenes per failure category

{_table(["category", "scenes"], cat_rows)}

## Scenes per failure generator

{_generators(rows)}

## Recoverability certificate

{EXPERT_TEXT[cfg.release.certify_expert]} was run from each scene up to
{cfg.release.certify_tries} times (horizon {cfg.release.certify_horizon} steps); a success
certifies the scene recoverable. Not certified is not a rejection; the column
`certify_reason` of `scenarios.parquet` says why. Certified: {certified} of {attempted} attempted.
{_uncertified(rows)}
## How it was made

- failure-generator policies: {", ".join(sorted({r.policy for r in rows})) or "(none)"}
- reviewers: {reviewers} distinct people; only final reviewed annotations are released
- prompt hashes:
{hashes}
- versions:
{vers}

Resolved configuration (output locations redacted):

```yaml
{yaml.safe_dump(portable_config(cfg), sort_keys=False).rstrip()}
```
"""
