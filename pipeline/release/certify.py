"""Recoverability certificate: can a zero-noise expert finish the task from a scene?

Inputs: scenes (task, BDDL, state) and the release config. Output per scene: tries made,
successes and, when none succeeded, why (`Certificate.reason`: the recovery expert's
give-up reason, `timeout` or `goal_not_reached`, see `pipeline.release.experts`); a
success certifies the scene recoverable. Not certified is not a rejection (it is shown to
reviewers and in the card). The expert is the recovery expert by default (`expert=plain`
runs the old one, for the before/after benchmark). Tries differ by seed; we stop at the
first success. Results are cached under `<release>/_build/certificates/` keyed by the
scene files' SHA-256, the expert and the try settings, so a rebuild after a crash redoes
only unfinished scenes. Scenes are grouped by task so each environment is built once.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from itertools import groupby
from pathlib import Path

import numpy as np
from rich.progress import Progress

from pipeline.atomic import write_json
from pipeline.config import Config
from pipeline.release.experts import RECOVERY, ExpertFactory, attempt, expert_factory, plain_expert
from pipeline.release.scene_physics import scene_task
from pipeline.sim import SimEnv

# bump when the experts change so cached certificates of an older expert are not reused
EXPERT_VERSION = {"plain": 3, "recovery": 4}


@dataclass(frozen=True)
class SceneRef:
    suite: str
    task: str
    instruction: str
    bddl: Path
    state: Path
    cache_key: str  # e.g. "<bddl sha>-<state sha>"


@dataclass(frozen=True)
class Certificate:
    tries: int
    successes: int
    reason: str | None = None  # why the last try failed, when none succeeded

    @property
    def certified(self) -> bool:
        return self.successes > 0


def make_expert(cfg: Config):
    """The plain scripted expert with every noise knob at zero (kept for benchmarks)."""
    return plain_expert(cfg)


def certify_one(env: SimEnv, state: np.ndarray, policy, tries: int, horizon: int, chunk_size: int) -> Certificate:
    """Up to `tries` attempts; `policy` is a built policy or an `ExpertFactory`."""
    reason = None
    for k in range(tries):
        pol = policy(env, k, 0.0) if callable(policy) and not hasattr(policy, "act") else policy
        try:
            out = attempt(env, state, pol, k, horizon, chunk_size)
        except Exception as e:  # an expert that crashes on one scene must not stop the release
            reason = f"expert_error: {type(e).__name__}: {e}"[:200]
            continue
        if out.success:
            return Certificate(tries=k + 1, successes=1)
        reason = out.reason
    return Certificate(tries=tries, successes=0, reason=reason)


def certify_all(scenes: list[SceneRef], cfg: Config, cache_dir: Path, expert: str = RECOVERY) -> dict[str, Certificate]:
    """Certificates by `cache_key`; empty when `certify_tries` is 0."""
    rc = cfg.release
    if rc.certify_tries == 0 or not scenes:
        return {}
    out: dict[str, Certificate] = {}
    suffix = f"{expert}{EXPERT_VERSION[expert]}-t{rc.certify_tries}-h{rc.certify_horizon}-c{cfg.stage1.rollout.chunk_size}"
    todo = []
    for s in scenes:
        f = cache_dir / f"{s.cache_key}-{suffix}.json"
        if f.is_file():
            out[s.cache_key] = Certificate(**json.loads(f.read_text()))
        else:
            todo.append(s)
    if not todo:
        return out
    factory: ExpertFactory = expert_factory(expert, cfg)
    todo.sort(key=lambda s: (s.suite, s.task, s.bddl.read_bytes()))
    with Progress(transient=True) as bar:
        job = bar.add_task(f"certifying scenes ({expert} expert)", total=len(todo))
        for _, group in groupby(todo, key=lambda s: (s.suite, s.task, s.bddl.read_bytes())):
            group = list(group)
            with SimEnv(scene_task(group[0].suite, group[0].task, group[0].instruction, group[0].bddl)) as env:
                for s in group:
                    cert = certify_one(env, np.load(s.state), factory, rc.certify_tries, rc.certify_horizon,
                                       cfg.stage1.rollout.chunk_size)
                    write_json(cache_dir / f"{s.cache_key}-{suffix}.json", asdict(cert))
                    out[s.cache_key] = cert
                    bar.advance(job)
    return out
