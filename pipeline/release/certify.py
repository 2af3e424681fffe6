"""Recoverability certificate: can a zero-noise expert finish the task from a scene?

Inputs: scenes (task, BDDL, state) and the release config. Output per scene: tries made,
successes and, when none succeeded, why (`Certificate.reason`: the recovery expert's
give-up reason, `timeout` or `goal_not_reached`, see `pipeline.release.experts`); a
success certifies the scene recoverable. Not certified is not a rejection (it is shown to
reviewers and in the card). The expert is the recovery expert by default (`expert=plain`
runs the old one, for the before/after benchmark). Tries differ by seed; we stop at the
first success.

Certification is a `Stage` (`CertifyStage`, one unit per scene) run by the `Runner` on the
configured executor (`inline`, `local`, `ray`): the certificate is the scene's done marker
(`<release>/_build/certificates/_done/<scene>.done`), whose recorded inputs are everything
that changes a certificate (the scene files' SHA-256, expert and its version, tries,
horizon, chunk size), so a rebuild redoes only scenes that are unfinished or whose inputs
changed. Scenes of one task and BDDL share a shard (one environment build); a scene whose
worker keeps dying, or that raises, is set aside with the reason (no certificate: the
manifest says not attempted, and the next build tries again).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline.config import Config
from pipeline.release.experts import RECOVERY, attempt, expert_factory, plain_expert
from pipeline.release.scene_physics import scene_task
from pipeline.runner import Stage, UnitResult, WorkerContext

if TYPE_CHECKING:
    from rich.console import Console

    from pipeline.executors import Executor
    from pipeline.sim import SimEnv

# bump when the experts change so cached certificates of an older expert are not reused
EXPERT_VERSION = {"plain": 5, "recovery": 32}


@dataclass(frozen=True)
class SceneRef:
    suite: str
    task: str
    instruction: str
    bddl: Path
    state: Path
    cache_key: str  # e.g. "<bddl sha>-<state sha>"
    unit_id: str = ""  # the scene's marker name (`layout.scene_unit`); default: cache_key

    @property
    def unit(self) -> str:
        return self.unit_id or self.cache_key


@dataclass(frozen=True)
class Certificate:
    tries: int
    successes: int
    reason: str | None = None  # why the last try failed, when none succeeded

    @property
    def certified(self) -> bool:
        return self.successes > 0


def scene_refs(rows, release: Path) -> list[SceneRef]:
    """The scenes of manifest rows (`ScenarioRow`s) of the release in `release`."""
    from pipeline.layout import episode_key, scene_unit

    return [SceneRef(r.suite, r.task, r.instruction, release / r.bddl_path, release / r.state_path,
                     f"{r.bddl_sha256[:16]}-{r.state_sha256[:16]}",
                     scene_unit(episode_key(r.suite, r.task, r.episode_id), r.step)) for r in rows]


def make_expert(cfg: Config):
    """The plain scripted expert with every noise knob at zero (kept for benchmarks)."""
    return plain_expert(cfg)


def certify_one(env: "SimEnv", state: np.ndarray, policy, tries: int, horizon: int, chunk_size: int) -> Certificate:
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


@dataclass
class CertifyStage(Stage[SceneRef]):
    """One unit per scene; its certificate is the marker's info (see the module docstring)."""

    cfg: Config
    scenes: list[SceneRef]
    folder: Path  # <release>/_build/certificates
    expert: str = RECOVERY
    name: str = "certify"

    @property
    def root(self) -> Path:
        return self.folder

    def units(self, cfg: Config) -> list[SceneRef]:
        return sorted(self.scenes, key=lambda s: (s.suite, s.task, s.cache_key, s.unit))

    def unit_id(self, scene: SceneRef) -> str:
        return scene.unit

    def fingerprint(self, scene: SceneRef) -> dict:
        rc = self.cfg.release
        return {"scene": scene.cache_key, "expert": f"{self.expert}{EXPERT_VERSION[self.expert]}",
                "tries": rc.certify_tries, "horizon": rc.certify_horizon, "chunk": self.cfg.stage1.rollout.chunk_size}

    def group(self, scene: SceneRef):
        return scene.suite, scene.task, scene.cache_key.split("-")[0]  # one model (task, BDDL) per shard

    def process(self, scene: SceneRef, ctx: WorkerContext) -> UnitResult:
        rc = self.cfg.release
        env = ctx.env(scene_task(scene.suite, scene.task, scene.instruction, scene.bddl))
        cert = certify_one(env, np.load(scene.state, allow_pickle=False), expert_factory(self.expert, self.cfg),
                           rc.certify_tries, rc.certify_horizon, self.cfg.stage1.rollout.chunk_size)
        return UnitResult(info=asdict(cert), ok=cert.certified,
                          status="certified" if cert.certified else "not certified", reason=cert.reason)

    def set_aside(self, scene: SceneRef, error: Exception) -> UnitResult:
        return UnitResult.set_aside(type(error).__name__, f"{scene.bddl}: {error}")

    def certificates(self) -> dict[str, Certificate]:
        """The current certificate of every scene that has one, by unit id."""
        from pipeline.runner.runner import finished

        return {unit: Certificate(**{k: info[k] for k in ("tries", "successes", "reason")})
                for unit, info in finished(self, self.scenes).items()}


def certify_all(scenes: list[SceneRef], cfg: Config, cache_dir: Path, expert: str = RECOVERY,
                executor: Executor | None = None, console: Console | None = None) -> dict[str, Certificate]:
    """Certificates by the scenes' `unit`, after running the missing ones on `executor` (default:
    the configured one); empty when `certify_tries` is 0. A scene set aside has none."""
    if cfg.release.certify_tries == 0 or not scenes:
        return {}
    from pipeline.executors import make_executor
    from pipeline.runner import Runner

    stage = CertifyStage(cfg, scenes, cache_dir, expert)
    Runner(executor or make_executor(cfg.executor), console=console).run(stage, cfg)
    return stage.certificates()
