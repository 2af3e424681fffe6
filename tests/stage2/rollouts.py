"""Fixture factory: a few real LIBERO episodes written in stage 1's run layout.

One task (libero_spatial 0: black bowl between plate and ramekin -> plate), init state 0,
short hand-made plans run through `pipeline.rollout.run_episode` on the real simulator:
    drop     grasps the target bowl, lifts it, opens mid-air     (truth: open at `DROP_STEP`)
    knock    sweeps a closed gripper through the other bowl      (truth: first robot contact)
    miss     closes the gripper 6 cm above the bowl's rim        (truth: close command)
    idle     does nothing                                        (no failure event at all)
    success  grasps the bowl and places it on the plate          (a success: stage 2 skips it)
The run folder is built once per plan-and-code version and cached (pytest cache), since
the episodes are deterministic.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.atomic import write_json, write_with
from pipeline.rendered import stamped
from pipeline.records import FRAME_SCHEMA, STEP_SCHEMA, EpisodeRecord, episode_id, episodes_table

SUITE = "libero_spatial"
TASK = "pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate"
TARGET, OTHER_BOWL = "akita_black_bowl_1", "akita_black_bowl_2"
O, C = -1.0, 1.0
PLANS = {
    "drop": [("hold", O, 10), ("move", TARGET, (0, 0.05, 0.15), O), ("move", TARGET, (0, 0.05, 0.03), O),
             ("hold", C, 15), ("move", TARGET, (0, 0.05, 0.20), C), ("hold", C, 5), ("hold", O, 45)],
    "knock": [("hold", C, 5), ("move", OTHER_BOWL, (0, 0.14, 0.15), C), ("move", OTHER_BOWL, (0, 0.14, 0.035), C),
              ("move", OTHER_BOWL, (0, -0.10, 0.035), C), ("hold", C, 20)],
    "miss": [("hold", O, 5), ("move", TARGET, (0, 0.05, 0.15), O), ("move", TARGET, (0, 0.05, 0.09), O),
             ("hold", C, 15), ("move", TARGET, (0, 0.05, 0.20), C), ("hold", C, 20)],
    "idle": [("hold", O, 40)],
    "success": [("hold", O, 10), ("move", TARGET, (0, 0.05, 0.15), O), ("move", TARGET, (0, 0.05, 0.03), O),
                ("hold", C, 15), ("move", TARGET, (0, 0.05, 0.20), C), ("move", "plate_1", (0, 0.05, 0.20), C),
                ("move", "plate_1", (0, 0.05, 0.08), C), ("hold", O, 30)],
}
HORIZON = {"drop": 175, "knock": 170, "miss": 150, "idle": 40, "success": 200}
SETTLE = 10
FPS = 10
VIDEO_PLANS, VIDEO_FPS = ("drop", "knock"), 2  # agentview videos, 64 px, for the VLM path


def _version() -> str:
    import pipeline.rollout
    import pipeline.sim.env
    import pipeline.stage1.video

    h = hashlib.sha256(json.dumps(PLANS, sort_keys=True).encode() + json.dumps(HORIZON).encode())
    for mod in (pipeline.rollout, pipeline.sim.env, pipeline.stage1.video, Path(__file__).with_name("scripted_moves.py")):
        h.update(Path(getattr(mod, "__file__", mod)).read_bytes())
    return h.hexdigest()[:12]


def _write_episode(root: Path, env, plan_name: str, policy) -> tuple[EpisodeRecord, dict]:
    from pipeline.rollout import run_episode

    env.reset_to_init(0)
    env.settle(SETTLE)
    policy.reset(env.task, 0)
    states = [env.get_state()]
    rows: list[dict] = []

    def on_step(info):
        pos, rot = env.eef_pose()
        rows.append({"step": info.step, "action": info.action.astype(np.float32).tolist(), "eef_pos": pos.tolist(),
                     "eef_quat": [1.0, 0.0, 0.0, 0.0], "gripper_qpos": env.gripper_qpos().tolist(),
                     "goal": info.goal, "query": info.query})
        states.append(env.get_state())

    res = run_episode(env, policy, horizon=HORIZON[plan_name], chunk_size=1, on_step=on_step)
    ep = episode_id(f"fixture_{plan_name}", 0, 0)
    rel = f"episodes/{SUITE}/{TASK}/{ep}"
    folder = root / "stage1" / rel
    arr = np.asarray(states)
    write_with(folder / "states.npy", lambda p: np.save(p, arr))
    write_with(folder / "steps.parquet", lambda p: pq.write_table(pa.Table.from_pylist(rows, STEP_SCHEMA), p))
    videos, fps = {}, FPS
    if plan_name in VIDEO_PLANS:  # a tiny real video for the VLM path (stage 1's own renderer)
        from pipeline.stage1.video import render_videos

        videos, fps = render_videos(env, arr, folder, ["agentview"], VIDEO_FPS, 64), VIDEO_FPS
    else:
        frames = [{"frame": i, "step": s, "time_s": s / 20} for i, s in enumerate(range(0, res.steps + 1, 20 // FPS))]
        write_with(folder / "frames.parquet", lambda p: pq.write_table(pa.Table.from_pylist(frames, stamped(FRAME_SCHEMA)), p))
    rec = EpisodeRecord(suite=SUITE, task=TASK, task_index=0, instruction=env.task.instruction, episode_id=ep,
                        init_state=0, policy=f"fixture_{plan_name}", policy_kind="scripted", seed=0, chunk_size=1,
                        horizon=HORIZON[plan_name], settle_steps=SETTLE, steps=res.steps, success=res.success,
                        first_success_step=res.first_success_step, wall_time_s=0.0, state_dim=env.state_dim,
                        path=rel, videos=videos, video_fps=fps)
    return rec, {"log": policy.log, "steps": res.steps}


def make_fixture_run(cache_dir: Path) -> Path:
    """A run folder with stage 1 done for the plans above; built once, then reused."""
    from pipeline.sim import build_env, get_task
    from tests.stage2.scripted_moves import WaypointPolicy

    root = Path(cache_dir) / f"run-{_version()}"
    if (root / "fixture.json").exists():
        return root
    env = build_env(get_task(SUITE, TASK))
    try:
        records, logs = [], {}
        for name, plan in PLANS.items():
            rec, logs[name] = _write_episode(root, env, name, WaypointPolicy(f"fixture_{name}", plan))
            records.append(rec)
    finally:
        env.close()
    table = episodes_table(records)
    write_with(root / "stage1" / "episodes.parquet", lambda p: pq.write_table(table, p))
    write_json(root / "fixture.json", logs)  # written last: the folder is complete
    return root


def plan_step(root: Path, plan: str, item: int) -> int:
    """The step at which plan item `item` started in the recorded episode."""
    logs = json.loads((root / "fixture.json").read_text())
    return next(s for s, label in logs[plan]["log"] if label.startswith(f"{item}:"))
