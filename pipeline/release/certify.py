"""Recoverability certificate: can the clean scripted expert finish the task from a scene?

Inputs: scenes (task, BDDL, state) and the release config. Output per scene: tries made and
successes; a success certifies the scene recoverable. Not certified is not a rejection (it is
shown to reviewers and in the card). Tries differ by seed; we stop at the first success.
Results are cached under `<release>/_build/certificates/` keyed by the scene files' SHA-256
and the try settings, so a rebuild after a crash redoes only unfinished scenes. Scenes are
grouped by task so each environment is built once.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from itertools import groupby
from pathlib import Path

import numpy as np
from rich.progress import Progress

from pipeline.atomic import write_json
from pipeline.config import Config, ScriptedNoise
from pipeline.release.scene_physics import restore_scene, scene_task
from pipeline.rollout import run_episode
from pipeline.sim import SimEnv


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

    @property
    def certified(self) -> bool:
        return self.successes > 0


def make_expert(cfg: Config):
    """The scripted expert with every noise knob at zero."""
    from pipeline.policies.scripted import make_scripted_policy

    clean = cfg.stage1.policy.scripted.model_copy(update={"noise": ScriptedNoise()})
    return make_scripted_policy(clean, name="scripted-expert")


def certify_one(env: SimEnv, state: np.ndarray, policy, tries: int, horizon: int, chunk_size: int) -> Certificate:
    for k in range(tries):
        restore_scene(env, state)
        policy.reset(env.task, k)
        if run_episode(env, policy, horizon, chunk_size, stop_on_success=True).success:
            return Certificate(tries=k + 1, successes=1)
    return Certificate(tries=tries, successes=0)


def certify_all(scenes: list[SceneRef], cfg: Config, cache_dir: Path) -> dict[str, Certificate]:
    """Certificates by `cache_key`; empty when `certify_tries` is 0."""
    rc = cfg.release
    if rc.certify_tries == 0 or not scenes:
        return {}
    out: dict[str, Certificate] = {}
    suffix = f"t{rc.certify_tries}-h{rc.certify_horizon}-c{cfg.stage1.rollout.chunk_size}"
    todo = []
    for s in scenes:
        f = cache_dir / f"{s.cache_key}-{suffix}.json"
        if f.is_file():
            out[s.cache_key] = Certificate(**json.loads(f.read_text()))
        else:
            todo.append(s)
    if not todo:
        return out
    policy = make_expert(cfg)
    todo.sort(key=lambda s: (s.suite, s.task, s.bddl.read_bytes()))
    with Progress(transient=True) as bar:
        job = bar.add_task("certifying scenes", total=len(todo))
        for _, group in groupby(todo, key=lambda s: (s.suite, s.task, s.bddl.read_bytes())):
            group = list(group)
            with SimEnv(scene_task(group[0].suite, group[0].task, group[0].instruction, group[0].bddl)) as env:
                for s in group:
                    cert = certify_one(env, np.load(s.state), policy, rc.certify_tries, rc.certify_horizon,
                                       cfg.stage1.rollout.chunk_size)
                    write_json(cache_dir / f"{s.cache_key}-{suffix}.json", {"tries": cert.tries, "successes": cert.successes})
                    out[s.cache_key] = cert
                    bar.advance(job)
    policy.close()
    return out
