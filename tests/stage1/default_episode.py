"""One episode of the default config made again by stage 1's own code (`run_one`), to turn a
case found on a run into a test: the generator is deterministic for (task, init state, seed)."""

from __future__ import annotations

from pathlib import Path

from pipeline.config import Config, load_config
from pipeline.policies.scripted import ScriptedPolicy
from pipeline.sim import SimEnv
from pipeline.stage1.units import EpisodeUnit
from pipeline.stage1.worker import run_one


def default_episode(env: SimEnv, out: Path, suite: str, task: str, init_state: int, seed: int, horizon: int) -> Path:
    """Run the scripted generator at the default noise for `horizon` steps; the episode's folder."""
    raw = load_config("configs/default.yaml").model_dump()
    raw["run"]["output_dir"] = str(out)
    raw["stage1"]["rollout"]["horizon"] = horizon
    raw["stage1"]["video"]["render"] = "none"
    cfg = Config.model_validate(raw)
    rec = run_one(env, ScriptedPolicy(cfg.stage1.policy.scripted), EpisodeUnit(suite, task, 0, init_state, seed, "scripted"),
                  cfg, out / "stage1")
    return out / "stage1" / rec.path
