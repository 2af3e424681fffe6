"""Stage 1 throughput, measured side by side in one run.

    .venv/bin/python benchmarks/stage1_throughput.py [--episodes 4] [--horizon 160]

First the control step itself (benchmarks/step_cost.py's measurement, one environment):
robosuite's `env.step` (before) and our fast step (after), against the 25 `mj_step` calls
inside a control step.

Modes, on the same episodes (same task, init states, policy and seeds, same artifacts:
states.npy, steps.parquet, agentview + wrist MP4 at --fps, frames.parquet):
  floor       physics only: reset, settle, policy + env.step; nothing recorded or rendered;
              with robosuite's step (the old floor) and with the fast step (the new one)
  ours        our stage 1 episode (`run_one`): physics-only rollout, then videos
              rendered from the logged states at --fps, at standard quality (LIBERO's
              look) and at fast quality (the stage default: no MSAA, no reflections;
              mean pixel difference 1.4/255), and with the stage's default render:
              failures, which skips the videos of successes; all of these render in
              this process after the physics (`run_one`), one core
  ours, render process   the stage's real path (the runner's `run_shard`, as a worker runs it): videos
              drawn by the worker's render process while the next episode's physics runs
              (pipeline/stage1/render_pool.py), at fast quality, all videos and failures
              only; this uses the second core
  naive       LIBERO's usual loop: `OffScreenRenderEnv` renders both cameras at every step;
              the frames at --fps go into the same videos
These run in this process on one prebuilt environment per mode (environment build
excluded; one core). "ours" is also run once with robosuite's step, for before/after.
Then the other stages that step the simulator, before/after in control steps per second:
the recoverability certificate (pipeline/release/certify.py's `certify_one`: clean expert,
stop at success, the release's certify horizon) from the episodes' init states, and an
evaluation trial (pipeline/eval/protocol.py's `run_trial`: perturbation, gripper settle,
the configured policy, stop at success) from the same states. Then `stage1.run` itself with 1 and with 2 local workers (spawn,
build, everything included), and with 2 workers without LP_NUM_THREADS=1, for the
worker speed-up. Other processes on the machine skew the wall times; rerun when quiet.
Every mode also prints its CPU time (this process plus its render process; for the
`stage1.run` modes, every worker and render process), which load barely changes: on a
busy machine compare those. With its render process one worker already runs two processes,
so on 2 cores 2 workers cannot beat 1 by more than 2 x wall(1 worker) / CPU(1 worker)
(capped at 2): the printed bound.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

from pipeline.config import load_config  # noqa: E402
from pipeline.rollout import run_episode  # noqa: E402
from pipeline.sim import SimEnv  # noqa: E402
from pipeline.sim.env import _quiet  # noqa: E402
from pipeline.stage1.recorder import EpisodeRecorder  # noqa: E402
from pipeline.stage1.units import plan_units  # noqa: E402
from pipeline.stage1.video import frame_steps, write_videos  # noqa: E402
from pipeline.stage1.worker import run_one  # noqa: E402


class NaiveLiberoEnv(SimEnv):
    """SimEnv's API over LIBERO's `OffScreenRenderEnv`, which renders every camera at every
    step (the loop of LIBERO's and openpi's evaluation scripts). Benchmark baseline only."""

    def __init__(self, task, cameras: list[str], size: int):
        from pipeline.sim.libero_setup import ensure_libero_ready

        ensure_libero_ready()
        with _quiet():
            from libero.libero.envs import OffScreenRenderEnv

            self._wrapper = OffScreenRenderEnv(
                bddl_file_name=str(task.bddl_path), camera_names=cameras, camera_heights=size,
                camera_widths=size, control_freq=20, horizon=10**9, ignore_done=True,
                hard_reset=False,  # LIBERO's default (True) would rebuild the model every reset: favour naive
            )
            self._wrapper.reset()
        self.task, self.env, self._renderers = task, self._wrapper.env, {}
        self._owner = self._body_owners()
        self.cameras = cameras
        self.last_obs: dict = {}

    def step(self, action: np.ndarray) -> bool:
        self.last_obs, _, done, _ = self.env.step(np.asarray(action, dtype=np.float64))
        return bool(done)

    def frames(self) -> dict[str, np.ndarray]:
        return {c: self.last_obs[f"{c}_image"][::-1] for c in self.cameras}  # robosuite: upside down


def floor_episode(env, policy, unit, cfg) -> None:
    r = cfg.stage1.rollout
    env.reset_to_init(unit.init_state)
    env.settle(r.settle_steps)
    policy.reset(env.task, unit.seed)
    run_episode(env, policy, r.horizon, r.chunk_size, r.stop_on_success)


def naive_episode(env: NaiveLiberoEnv, policy, unit, cfg, out: Path) -> None:
    r, v = cfg.stage1.rollout, cfg.stage1.video
    env.reset_to_init(unit.init_state)
    env.settle(r.settle_steps)
    policy.reset(env.task, unit.seed)
    rec = EpisodeRecorder(env)
    env.last_obs = env._wrapper.env._get_observations(force_update=True)  # renders the first frame
    stride = 20 // v.fps
    frames = {c: [] for c in env.cameras}
    kept: list[int] = []

    def keep(step: int) -> None:
        kept.append(step)
        for c, img in env.frames().items():
            frames[c].append(img.copy())

    keep(0)

    def on_step(info) -> None:
        rec.on_step(info)
        if (info.step + 1) % stride == 0:
            keep(info.step + 1)

    res = run_episode(env, policy, r.horizon, r.chunk_size, r.stop_on_success, on_step=on_step)
    if kept[-1] != res.steps:
        keep(res.steps)
    assert kept == frame_steps(res.steps, v.fps)
    folder = out / unit.rel_dir
    rec.write(folder)
    write_videos(frames, kept, folder, v.fps)


def counting(env: SimEnv) -> list[int]:
    """Count `env.step` calls (an instance attribute shadows the method)."""
    n = [0]
    step = type(env).step

    def counted(action):
        n[0] += 1
        return step(env, action)

    env.step = counted
    return n


def other_stages(env: SimEnv, policy, units, cfg, tmp: Path) -> None:
    """Certificate and eval trial: control steps per second with robosuite's step and ours."""
    from pipeline.eval.protocol import Trial, run_trial
    from pipeline.eval.scenes import Scene
    from pipeline.release.certify import certify_one, make_expert

    expert = make_expert(cfg)
    n = counting(env)
    scenes = []
    for u in units:
        path = tmp / f"scene-{u.init_state}.npy"
        np.save(path, env.task.init_states()[u.init_state])
        scenes.append(Scene(suite=env.task.suite, task=env.task.name, episode_id=f"bench-i{u.init_state:02d}", step=0,
                            bddl_path=env.task.bddl_path, state_path=path, init_state=u.init_state))
    jobs = {
        "certificate": lambda s: certify_one(env, np.load(s.state_path), expert, cfg.release.certify_tries,
                                             cfg.release.certify_horizon, cfg.stage1.rollout.chunk_size),
        "eval trial": lambda s: run_trial(env, policy, Trial(
            scene=s, policy="bench", policy_kind=cfg.stage1.policy.kind, gripper="open", trial=0, seed=0,
            chunk_size=cfg.stage1.rollout.chunk_size, horizon=cfg.eval.horizon, max_offset_m=cfg.eval.max_offset_m,
            gripper_settle_steps=cfg.eval.gripper_settle_steps)),
    }
    for label, job in jobs.items():
        rates = {}
        for fast in (False, True):
            env.fast_step = fast
            n[0] = 0
            t0 = time.perf_counter()
            for s in scenes:
                job(s)
            rates[fast] = n[0] / (time.perf_counter() - t0)
        print(f"  {label:<28} {rates[False]:6.1f} -> {rates[True]:6.1f} control steps/s "
              f"(robosuite step -> fast step, {n[0]} steps): {rates[True] / rates[False]:.2f}x", flush=True)
    env.fast_step = True
    del env.step
    expert.close()


def cpu_s(pids: tuple[int, ...] = ()) -> float:
    """CPU seconds of this process (all threads: llvmpipe's too) and the live processes `pids`."""
    total = time.process_time()
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime
        except (OSError, IndexError, ValueError):
            pass
    return total


def children_cpu_s() -> float:
    """CPU seconds of every finished child (workers and their render processes, once reaped)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(label: str, fn, units) -> float:
    t0, c0 = time.perf_counter(), cpu_s()
    for u in units:
        fn(u)
    return report(label, time.perf_counter() - t0, len(units), cpu_s() - c0)


def report(label: str, dt: float, n: int, cpu: float | None = None) -> float:
    extra = f"  cpu {cpu:7.1f} s ({cpu / n:.2f} s/episode)" if cpu is not None else ""
    print(f"  {label:<28} {dt:8.1f} s  {n / dt * 3600:8.0f} episodes/hour{extra}", flush=True)
    return dt


def one_core(args, task, cfg, units, tmp: Path) -> None:
    """The in-process comparisons: control step, floors, ours, other stages, naive."""
    from pipeline.policies.factory import make_policy

    from step_cost import control_step_costs

    c = control_step_costs(task, steps=args.horizon)
    print(f"control step ({task.task_id}, scripted expert with noise, ms): robosuite {c['robosuite']:.2f} -> fast "
          f"{c['fast']:.2f} ({c['robosuite'] / c['fast']:.2f}x); the 25 mj_step inside {c['mj_step']:.2f} "
          f"(robosuite {c['robosuite'] / c['mj_step']:.2f}x it, fast {c['fast'] / c['mj_step']:.2f}x); "
          f"fast's own physics, 25 x (mj_step1 + mj_step2): {c['split']:.2f}", flush=True)

    print("one core, in process (environment build excluded):")
    env = SimEnv(task)
    for quality in ("standard", "fast"):  # renderer creation is a one-off per process: keep it out
        for cam in ("agentview", "robot0_eye_in_hand"):
            env.render(cam, args.resolution, quality)
    policy = make_policy(cfg.stage1.policy)
    env.fast_step = False
    t_floor_old = timed("floor, robosuite step (old)", lambda u: floor_episode(env, policy, u, cfg), units)
    env.fast_step = True
    t_floor = timed("physics-only floor (new)", lambda u: floor_episode(env, policy, u, cfg), units)
    def video(**kw):
        return cfg.model_copy(update={"stage1": cfg.stage1.model_copy(update={
            "video": cfg.stage1.video.model_copy(update=kw)})})

    std_cfg, fast_cfg = video(quality="standard"), video(quality="fast")
    t_std = timed("ours, standard video quality", lambda u: run_one(env, policy, u, std_cfg, tmp / "std"), units)
    t_ours = timed("ours, fast video quality", lambda u: run_one(env, policy, u, fast_cfg, tmp / "ours"), units)
    env.fast_step = False
    t_ours_old = timed("ours, fast video, old step", lambda u: run_one(env, policy, u, fast_cfg, tmp / "old"),
                       units)
    env.fast_step = True
    fail_cfg = video(quality="fast", render="failures")
    t_fail = timed("ours, default (failure videos)", lambda u: run_one(env, policy, u, fail_cfg, tmp / "fail"), units)
    t_pool, t_pool_fail = render_process_modes(units, fast_cfg, fail_cfg, tmp)
    print("other stages that step the simulator (same init states):")
    other_stages(env, policy, units, cfg, tmp)
    env.close()
    naive_env = NaiveLiberoEnv(task, ["agentview", "robot0_eye_in_hand"], args.resolution)
    t_naive = timed("naive LIBERO loop", lambda u: naive_episode(naive_env, policy, u, cfg, tmp / "naive"), units)
    naive_env.close()
    print(f"  naive / ours: {t_naive / t_std:.2f}x at standard quality (LIBERO's look; naive renders "
          f"{20 // args.fps}x the frames), {t_naive / t_ours:.2f}x at fast quality (the stage default: no "
          f"MSAA, no reflections), {t_naive / t_fail:.2f}x with videos of failures only; "
          f"ours (fast) is {t_ours / t_floor:.2f}x the physics-only floor; the fast step made the floor "
          f"{t_floor_old / t_floor:.2f}x and ours {t_ours_old / t_ours:.2f}x faster")
    print(f"  with the render process (the stage's path): naive / ours {t_naive / t_pool:.2f}x at fast quality, "
          f"{t_naive / t_pool_fail:.2f}x with videos of failures only; ours is {t_pool / t_floor:.2f}x the "
          f"physics-only floor ({t_pool_fail / t_floor:.2f}x with failure videos only); the render process made "
          f"ours {t_ours / t_pool:.2f}x faster than rendering after the physics")


def render_process_modes(units, fast_cfg, fail_cfg, tmp: Path) -> tuple[float, float]:
    """The runner's `run_shard` in this process, as a worker runs it: its cached environment and render
    process are warmed by one episode first (build excluded, like the other modes)."""
    from pipeline.runner import WorkerContext
    from pipeline.runner.runner import run_shard
    from pipeline.stage1.stage import Stage1

    ctx = WorkerContext()  # this process as one worker: env and render process kept across shards

    def shard(cfg, units, folder) -> None:
        cfg = cfg.model_copy(update={"run": cfg.run.model_copy(update={"output_dir": tmp / folder})})
        run_shard((Stage1(cfg), tuple(units)), ctx)

    shard(fast_cfg, units[:1], "warm")
    render_pid = (ctx.peek("render")._proc.pid,)
    out = []
    for label, cfg in (("ours, render process", fast_cfg), ("ours, render process, failures", fail_cfg)):
        t0, c0 = time.perf_counter(), cpu_s(render_pid)
        shard(cfg, units, label.replace(" ", "_").replace(",", ""))
        out.append(report(label, time.perf_counter() - t0, len(units), cpu_s(render_pid) - c0))
    ctx.close()
    return out[0], out[1]



def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/smoke.yaml", help="policy and noise come from here")
    ap.add_argument("--suite", default="libero_spatial")
    ap.add_argument("--task-index", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=4)
    ap.add_argument("--horizon", type=int, default=160)
    ap.add_argument("--fps", type=int, default=4, help="video fps (the configs use 4)")
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--skip-workers", action="store_true", help="only the one-core comparison")
    ap.add_argument("--workers-only", action="store_true",
                    help="only stage1.run with 1 and 2 workers (use more --episodes: each worker builds its environment once)")
    args = ap.parse_args()

    from pipeline.sim.registry import tasks as list_tasks
    from pipeline.stage1.run import run

    task = list_tasks([args.suite])[args.task_index]
    tmp = Path(tempfile.mkdtemp(prefix="stage1-bench-"))
    cfg = load_config(args.config, {
        "run.output_dir": str(tmp / "inproc"), "tasks.suites": [args.suite], "tasks.tasks": [task.name],
        "tasks.max_tasks_per_suite": None, "tasks.init_states": list(range(args.episodes)),
        "stage1.rollout.horizon": args.horizon, "stage1.rollout.stop_on_success": False,
        "stage1.video.cameras": ["agentview", "robot0_eye_in_hand"], "stage1.video.fps": args.fps,
        "stage1.video.resolution": args.resolution, "stage1.video.render": "all",
    })
    units = plan_units(cfg)
    print(f"{len(units)} episodes of {task.task_id}, horizon {args.horizon} (no early stop), "
          f"2 cameras {args.resolution}px at {args.fps} fps, policy {cfg.stage1.policy.kind}; output {tmp}")

    if not args.workers_only:
        one_core(args, task, cfg, units, tmp)
    if args.skip_workers:
        return
    print("stage1.run end to end (spawn + build + episodes), local executor:")
    import pipeline.stage1.run as run_mod
    from rich.console import Console

    quiet = Console(file=open(os.devnull, "w"))
    walls, cpus = {}, {}
    for label, workers, env_vars in (("1 worker", 1, {"LP_NUM_THREADS": "1"}), ("2 workers", 2, {"LP_NUM_THREADS": "1"}),
                                     ("2 workers, Mesa default", 2, {})):
        run_mod.WORKER_ENV = env_vars
        c = cfg.model_copy(update={
            "run": cfg.run.model_copy(update={"output_dir": tmp / label.replace(" ", "_").replace(",", "")}),
            "executor": cfg.executor.model_copy(update={"workers": workers})})
        t0, c0 = time.perf_counter(), children_cpu_s()
        run(c, console=quiet)
        walls[label] = dt = time.perf_counter() - t0
        cpus[label] = children_cpu_s() - c0
        report(label, dt, len(units), cpus[label])
    bound = min(2.0, 2 * walls["1 worker"] / cpus["1 worker"])
    print(f"  speed-up 2 workers vs 1: {walls['1 worker'] / walls['2 workers']:.2f}x (bound on 2 cores from 1 worker's "
          f"CPU/wall: {bound:.2f}x); LP_NUM_THREADS=1 vs Mesa default with 2 workers: "
          f"{walls['2 workers, Mesa default'] / walls['2 workers']:.2f}x wall, "
          f"{cpus['2 workers, Mesa default'] / cpus['2 workers']:.2f}x CPU")


if __name__ == "__main__":
    main()
