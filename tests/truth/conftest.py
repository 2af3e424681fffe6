"""A run folder of two hand-built failures of the scripted generator on the real simulator,
written by stage 1's own `run_one` (states, steps, truth, video), once per session:
    miss  the grasp point is forced 6 cm above the bowl's rim: the fingers close on air
    drop  the gripper is forced open at a known step while the bowl is carried
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.config import Config, ScriptedPolicyConfig
from pipeline.policies.scripted import ScriptedPolicy
from pipeline.policies.scripted.noise import Noise
from pipeline.records import episodes_table
from pipeline.stage1.units import EpisodeUnit

SUITE = "libero_spatial"
TASK = "pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate"
TARGET = "akita_black_bowl_1"
HORIZON = 150


class ForcedDrop:
    """The clean expert, except that from the first chunk asked while it carries the bowl
    towards the plate, the gripper is commanded open: a drop at a known step."""

    def __init__(self, cfg: ScriptedPolicyConfig):
        self.inner = ScriptedPolicy(cfg, "scripted_drop")
        self.name, self.cameras, self.image_size = "scripted_drop", (), 224
        self.forced_at: int | None = None

    def reset(self, task, seed):
        self.inner.reset(task, seed)
        self.forced_at = None

    def act(self, obs):
        chunk = self.inner.act(obs).copy()
        left, right = obs.sim.finger_contacts()
        carrying = TARGET in left and TARGET in right and self.inner.phase in ("lift", "transport")
        if self.forced_at is None and carrying and obs.step > 0:
            self.forced_at = obs.step
        if self.forced_at is not None:
            chunk[:, 6] = -1.0
        return chunk

    def on_step(self, step, action):
        self.inner.on_step(step, action)

    def truth_table(self):
        return self.inner.truth_table()

    def params(self):
        return {"kind": "scripted", "forced": "drop"}

    def close(self):
        self.inner.close()


@pytest.fixture(scope="session")
def truth_run(tmp_path_factory) -> tuple[Path, dict]:
    """(run folder, {"miss": EpisodeRecord, "drop": EpisodeRecord, "drop_step": int})."""
    from pipeline.atomic import write_with
    from pipeline.sim import build_env, get_task
    from pipeline.stage1.worker import run_one

    import pyarrow.parquet as pq

    root = tmp_path_factory.mktemp("truth_run")
    cfg = Config.model_validate({
        "run": {"output_dir": str(root)},
        "stage1": {"rollout": {"horizon": HORIZON, "chunk_size": 8},
                   "video": {"cameras": ["agentview"], "fps": 4, "resolution": 64, "quality": "fast"}},
    })
    clean = ScriptedPolicyConfig(max_attempts=1)
    env = build_env(get_task(SUITE, TASK))
    out = {}
    try:
        with pytest.MonkeyPatch.context() as mp:  # the grasp point 6 cm too high, nothing else
            mp.setattr(Noise, "grasp_offset", lambda self: np.array([0.0, 0.0, 0.06]))
            unit = EpisodeUnit(SUITE, TASK, 0, 0, 0, "scripted_miss")
            out["miss"] = run_one(env, ScriptedPolicy(clean, "scripted_miss"), unit, cfg, root / "stage1")
        drop = ForcedDrop(clean)
        out["drop"] = run_one(env, drop, EpisodeUnit(SUITE, TASK, 0, 0, 0, "scripted_drop"), cfg, root / "stage1")
        out["drop_step"] = drop.forced_at
    finally:
        env.close()
    table = episodes_table([out["miss"], out["drop"]])
    write_with(root / "stage1" / "episodes.parquet", lambda p: pq.write_table(table, p))
    return root, out
