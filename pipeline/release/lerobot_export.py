"""`recover export-lerobot`: rollouts and pre-failure histories as LeRobot v2.1 datasets.

Inputs: stage 1 (`episodes.parquet`, each episode's `states.npy` + `steps.parquet`) and the
release manifest (`scenarios.parquet`, for the histories), and the recovery demos
(`<run>/recoveries/demos.parquet`, `recover demos`). Outputs under `out` (default
`<run>/lerobot/`): `rollouts/` (stage 1 episodes: all or failures only, per config),
`pre_failure_histories/` (each released scene's episode up to its failure step) and
`recoveries/` (the recovery demos, rendered in their scene's own BDDL model; task = the
original instruction; episodes.jsonl also names each demo's scene id, level and
category), each a LeRobot v2.1 dataset (`pipeline.release.lerobot_format`). Frames are rendered from the
logged states at 20 Hz (every control step), third-person and wrist cameras
(`observation.images.image`, `observation.images.image2`) as LeRobot's LIBERO env shows them to a
policy (robosuite's raw image turned 180 degrees; `FORMAT_VERSION` below), at
`release.lerobot_render_quality` (standard: LIBERO's look); state = eef position, eef
axis-angle (of robosuite's `robot0_eef_quat`), the two gripper finger positions (8-D, as in LIBERO's LeRobot datasets), with the
arm's joint states beside it (`observation.states.joint_state`: the 7 joint positions;
`observation.states.gripper_state`: the 2 finger joints); action = the 7-D command, float32 as
in LIBERO's LeRobot datasets, and beside it `action_float64`, the same command exactly as the
simulator stepped it (the source episode's `actions.npy`): only those replay bit for bit.
`episodes.jsonl` says where each episode began (`init_state` and `settle_steps` of a rollout or
history, `scene_id` of a demo). Before an episode is written its actions are replayed in plain
LIBERO from where it began (`pipeline.release.replay`: a rollout or history from its init state
and stage 1's settle, a demo from its scene) and must give its logged states bit for bit, or
the episode is set aside.

Episodes are rendered in parallel as a `Stage` (pipeline/runner/) on the run's executor: one
unit per episode, the episodes of one simulator model (suite, task, BDDL content) share a
shard, so a worker builds each model once. A worker writes an episode's files, then its
entry (`<out>/_work/<dataset>/<i>.json`), then the runner its done-marker (`_work/<dataset>/_done`):
resumable. The parent writes the meta files last, from the entries in episode order, so a
dataset is the same, byte for byte, whatever the number of workers. An episode that fails is
set aside with the reason and the others go on; its dataset then gets no meta files and the
export fails naming it (a rerun does only what is missing).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from rich.console import Console

from pipeline.atomic import write_json, write_with
from pipeline.config import Config
from pipeline.errors import ConfigError, FatalError
from pipeline.layout import EpisodeFiles, RunLayout, Stage1Layout, episode_key
from pipeline.records import EpisodeRecord, read_episodes
from pipeline.release import lerobot_format as fmt
from pipeline.release.manifest import MANIFEST_NAME
from pipeline.release.replay import ReplayStart, check_exported
from pipeline.release.scene_physics import scene_task
from pipeline.runner import Stage, UnitResult, WorkerContext
from pipeline.sim import SimEnv, TaskSpec, get_task
from pipeline.sim.pool import model_key
from pipeline.sim.render import RENDERER_VERSION


@dataclass
class ExportEpisode:
    key: str  # the source (`suite/task/episode_id`, plus `@<step>` for histories)
    suite: str
    task: str
    instruction: str
    folder: Path  # stage 1 episode folder
    length: int  # frames to export (states[:length], actions[:length])
    bddl: Path | None = None  # the scene's own BDDL (recovery demos); None: the task's
    meta: dict = field(default_factory=dict)  # extra episodes.jsonl fields
    start: ReplayStart | None = None  # where it began: its actions must replay from there
    split: str = "train"  # its side of the release's train/eval split (info.json's `splits`)

    def spec(self) -> TaskSpec:
        """The task whose model renders it (with the scene's own BDDL where it has one)."""
        if self.bddl is None:
            return get_task(self.suite, self.task)
        return scene_task(self.suite, self.task, self.instruction, self.bddl)


# The dataset's convention (format version 2) is what LeRobot's LIBERO env gives a policy
# (`lerobot/envs/libero.py` + its `LiberoProcessorStep`, the convention of LIBERO's LeRobot datasets),
# so a policy trained on it runs unchanged under `lerobot-eval --env.type=libero` and `policy.kind:
# lerobot`: images are robosuite's raw image turned 180 degrees (our right-side-up frame mirrored
# left-right), state = eef position, axis-angle of robosuite's `robot0_eef_quat`, gripper qpos.
# Version 1 (before): frames right side up, the axis-angle of the grip site's rotation.
FORMAT_VERSION = 2


def libero_frame(frame: np.ndarray) -> np.ndarray:
    """Our right-side-up frame as LeRobot's LIBERO env shows it: robosuite's raw image (ours
    flipped vertically) turned 180 degrees, i.e. ours mirrored left-right."""
    return np.ascontiguousarray(frame[:, ::-1])


def libero_state(env: SimEnv) -> np.ndarray:
    """The 8-D state of LeRobot's LIBERO env for the current simulator state."""
    from pipeline.policies.openpi_policy import quat_xyzw_to_axis_angle

    r = env.robot_observables()
    return np.concatenate([r["robot0_eef_pos"], quat_xyzw_to_axis_angle(r["robot0_eef_quat"]),
                           r["robot0_gripper_qpos"]])


def render_episode(env: SimEnv, states: np.ndarray, size: int,
                   quality: str = "standard") -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """8-D robot states and frames per LeRobot video key for each logged simulator state."""
    robot, frames = [], {k: [] for k in fmt.VIDEO_KEYS}
    for s in states:
        env.set_state(s)
        robot.append(libero_state(env))
        for key, cam in fmt.VIDEO_KEYS.items():
            frames[key].append(libero_frame(env.render(cam, size, quality)))
    return np.asarray(robot), {k: np.stack(v) for k, v in frames.items()}


def joint_states(env: SimEnv, states: np.ndarray) -> np.ndarray:
    """The arm's 7 joint positions (robot0_joint1..7) for each logged simulator state."""
    out = []
    for s in states:
        env.set_state(s)
        out.append(env.arm_joints()[0])
    return np.asarray(out).reshape(len(states), 7)


def write_video(path: Path, frames: np.ndarray) -> None:
    import av

    from pipeline.h264 import repeatable

    def encode(tmp: Path) -> None:
        with av.open(str(tmp), "w", format="mp4") as box:
            stream = box.add_stream("libx264", rate=fmt.FPS)
            stream.width, stream.height = frames.shape[2], frames.shape[1]
            stream.pix_fmt = "yuv420p"
            # short GOP: cheap random access for loaders; repeatable: the same frames give the
            # same bytes with any worker count (crf 22 without mb-tree ~ the old crf 20's size)
            repeatable(stream, crf=22, g="2")
            for f in frames:
                box.mux(stream.encode(av.VideoFrame.from_ndarray(f, format="rgb24")))
            box.mux(stream.encode())

    write_with(path, encode)


def start_meta(e) -> dict:
    """Where a stage-1 episode began (episodes.jsonl): LIBERO's init state `init_state` of its
    task, restored as the card says, then `settle_steps` actions [0, 0, 0, 0, 0, 0, -1]."""
    return {"init_state": e.init_state, "settle_steps": e.settle_steps}
def by_split(episodes: list[ExportEpisode]) -> list[ExportEpisode]:
    """Train episodes first, then eval (LeRobot's `splits` are index ranges), each by key."""
    return sorted(episodes, key=lambda x: (x.split != "train", x.key))


def eval_episode_keys(manifest: Path) -> set[str]:
    """Stage-1 episodes a released eval scene was cut from: their rollouts lead into held-out
    scenes, so they sit in the eval split of the rollouts dataset."""
    from pipeline.release.manifest import read_manifest

    if not manifest.is_file():
        return set()
    return {episode_key(r.suite, r.task, r.episode_id) for r in read_manifest(manifest) if r.split == "eval"}


def stage1_episodes(cfg: Config) -> list[tuple[Stage1Layout, EpisodeRecord]]:
    """(stage-1 layout, episode) of this run and of every `release.merge_runs` run."""
    layouts = [RunLayout.of(cfg).stage1] + [RunLayout(Path(r)).stage1 for r in cfg.release.merge_runs]
    return [(st, e) for st in layouts for e in read_episodes(st.manifest)]


def rollout_episodes(cfg: Config) -> list[ExportEpisode]:
    layout = RunLayout.of(cfg)
    held_out = eval_episode_keys(layout.release.manifest)
    out = []
    for stage1, e in stage1_episodes(cfg):
        if cfg.release.lerobot_episodes == "failures" and e.success:
            continue
        out.append(ExportEpisode(e.key, e.suite, e.task, e.instruction, stage1.episode(e).dir, e.steps,
                                 meta=start_meta(e), start=ReplayStart(init_state=e.init_state,
                                                                       settle_steps=e.settle_steps),
                                 split="eval" if e.key in held_out else "train"))
    return by_split(out)


def history_episodes(cfg: Config, manifest: Path) -> list[ExportEpisode]:
    from pipeline.release.manifest import read_manifest

    if not manifest.is_file():
        return []
    eps = {e.key: (stage1, e) for stage1, e in stage1_episodes(cfg)}  # merged runs' too
    out = []
    for r in read_manifest(manifest):
        stage1, e = eps.get(episode_key(r.suite, r.task, r.episode_id), (None, None))
        if e is not None and r.fail_step >= 1:
            out.append(ExportEpisode(f"{e.key}@{r.step}", r.suite, r.task, r.instruction, stage1.episode(e).dir,
                                     min(r.fail_step, e.steps), meta=start_meta(e),
                                     start=ReplayStart(init_state=e.init_state, settle_steps=e.settle_steps),
                                     split="eval" if r.split == "eval" else "train"))
    return by_split(out)


def recovery_episodes(cfg: Config, release: Path) -> list[ExportEpisode]:
    from pipeline.release.manifest import read_manifest
    from pipeline.release.recovery_demos import read_demos, scene_id

    recoveries = RunLayout.of(cfg).recoveries
    root = recoveries.root
    if not recoveries.demos.is_file() or not (release / MANIFEST_NAME).is_file():
        return []
    # demos of eval scenes (recorded before the release had a split) would leak held-out scenes
    rows = {scene_id(r): r for r in read_manifest(release / MANIFEST_NAME) if r.split != "eval"}
    bddl = {sid: release / r.bddl_path for sid, r in rows.items()}
    out = []
    for d in read_demos(recoveries.demos):
        if d.scene_id not in bddl:  # a demo of a scene no longer released (or now held out)
            continue
        out.append(ExportEpisode(f"{d.scene_id}/demo_{d.demo_index}", d.suite, d.task, d.instruction, root / d.path,
                                 d.steps, bddl[d.scene_id],
                                 {"scene_id": d.scene_id, "level": d.level, "category": d.category},
                                 ReplayStart(scene_state=release / rows[d.scene_id].state_path)))
    return sorted(out, key=lambda x: x.key)


def export_episode(env: SimEnv, ep: ExportEpisode, i: int, start: int, task_index: int, root: Path,
                   size: int, quality: str = "standard") -> dict:
    """Render and write episode `i`; return its episodes.jsonl/episodes_stats.jsonl entry."""
    files = EpisodeFiles(ep.folder)
    if ep.start is not None:  # what is exported is the rollout it claims to be, or nothing
        problems = check_exported(env, ep.start, ep.folder, ep.length)
        if problems:
            raise ValueError("; ".join(problems))
    states = np.load(files.states)[: ep.length]
    actions = np.load(files.actions, allow_pickle=False)[: ep.length]  # float64, as stepped
    robot, frames = render_episode(env, states, size, quality)
    table = fmt.frame_table(robot, actions, i, start, task_index, joint_states(env, states))
    write_with(root / fmt.data_path(i), lambda p: pq.write_table(table, p))
    for key, f in frames.items():
        write_video(root / fmt.video_path(i, key), f)
    return {"episode_index": i, "tasks": [ep.instruction], "length": ep.length, "source": ep.key,
            "meta": ep.meta, "split": ep.split, "stats": fmt.episode_stats(table, frames)}


@dataclass
class ExportUnit:
    """Episode `index` of a dataset, with what its files need from the whole dataset."""

    index: int
    start: int  # its first frame's dataset-wide `index`
    task_index: int
    episode: ExportEpisode
    model: tuple[str, str]  # the simulator model it is rendered in (`model_key`: one per shard)

    @property
    def unit_id(self) -> str:
        return f"{self.index:06d}"


def plan_units(episodes: list[ExportEpisode]) -> tuple[list[ExportUnit], list[str]]:
    """One unit per episode, ordered by model (then index), and the dataset's task list."""
    tasks = sorted({e.instruction for e in episodes})
    starts = np.concatenate([[0], np.cumsum([e.length for e in episodes])]).astype(int)
    # scenes of one task often share their BDDL text: one model, one build
    units = [ExportUnit(i, int(starts[i]), tasks.index(ep.instruction), ep, model_key(ep.spec()))
             for i, ep in enumerate(episodes)]
    return sorted(units, key=lambda u: (u.model, u.index)), tasks


@dataclass
class ExportStage(Stage[ExportUnit]):
    """Renders and writes one dataset's episodes (the meta files are the parent's: `export_dataset`)."""

    dataset: str  # its folder
    work: str  # `_work/<dataset>`: episode entries and done-markers
    size: int
    quality: str
    planned: list[ExportUnit]

    @property
    def name(self) -> str:
        return f"LeRobot {Path(self.dataset).name}"

    @property
    def root(self) -> Path:
        return Path(self.work)

    def units(self, cfg=None) -> list[ExportUnit]:
        return self.planned

    def group(self, unit: ExportUnit) -> tuple[str, str]:
        return unit.model

    def fingerprint(self, unit: ExportUnit) -> dict:
        return {"renderer_version": RENDERER_VERSION, "format_version": FORMAT_VERSION}

    def process(self, unit: ExportUnit, ctx: WorkerContext) -> UnitResult:
        ep = unit.episode
        env = ctx.env(ep.spec())
        meta = export_episode(env, ep, unit.index, unit.start, unit.task_index, Path(self.dataset), self.size,
                              self.quality)
        write_json(self.root / f"{unit.unit_id}.json", meta)  # before the marker (the runner's, last)
        return UnitResult(ok=True)  # the bar's "ok n/m": episodes written

    def set_aside(self, unit: ExportUnit, error: Exception) -> UnitResult:
        return UnitResult.set_aside(type(error).__name__, f"{unit.episode.key}: {error}")


def refuse_old_renders(stage: ExportStage, units: list[ExportUnit]) -> None:
    """An export resumed over episodes drawn by an older renderer, or in the older convention
    (format version 1: other orientation and state), would mix two looks in one training set
    (markers of those carry neither version): refuse, naming the fix."""
    from pipeline.runner.runner import recorded_inputs

    done = recorded_inputs(stage, units)
    old = [u for u in units if stage.unit_id(u) in done and done[stage.unit_id(u)] != stage.fingerprint(u)]
    if old:
        raise FatalError(f"export-lerobot {Path(stage.dataset).name}: {len(old)} episode(s) in {stage.dataset} were "
                         f"rendered by an older renderer or in the older image and state convention (now renderer "
                         f"{RENDERER_VERSION}, format {FORMAT_VERSION}); "
                         f"delete {stage.dataset} and {stage.work} and run `recover export-lerobot --config <this "
                         f"run's config>` again to re-render them")


def export_dataset(episodes: list[ExportEpisode], root: Path, work: Path, size: int, runner,
                   quality: str = "standard") -> int:
    """Write one v2.1 dataset on `runner` (a `pipeline.runner.Runner`); return its frame count.
    Raises FatalError naming the episodes set aside (no meta files then)."""
    units, tasks = plan_units(episodes)
    stage = ExportStage(str(root), str(work), size, quality, units)
    refuse_old_renders(stage, units)
    todo = runner.pending(stage, units)
    stats = runner.execute(stage, todo, done_before=len(units) - len(todo))
    if stats.set_aside:
        raise FatalError(f"export-lerobot {root.name}: {len(stats.set_aside)} episode(s) set aside, no meta "
                         f"written (rerun to retry them): " + "; ".join(
                             f"{ev.unit}: {ev.reason}: {(ev.detail or '').strip()[:200]}" for ev in stats.set_aside))
    metas = [json.loads((work / f"{i:06d}.json").read_text()) for i in range(len(episodes))]
    fmt.write_meta(root, metas, tasks, size)
    return sum(e.length for e in episodes)


DATASETS = ("rollouts", "pre_failure_histories", "recoveries")


def run(cfg: Config, out: Path | None = None, only: list[str] | None = None) -> Path:
    """Export every dataset, or those named in `only`."""
    layout = RunLayout.of(cfg)
    out = Path(out or cfg.release.lerobot_dir or layout.lerobot)
    size = cfg.release.lerobot_image_size
    if size % 2:
        raise ConfigError(f"release.lerobot_image_size must be even for yuv420p video, got {size}")
    bad = sorted(set(only or []) - set(DATASETS))
    if bad:
        raise ConfigError(f"export-lerobot: unknown dataset(s) {bad}; choose from {list(DATASETS)}")
    sources = {"rollouts": lambda: rollout_episodes(cfg),
               "pre_failure_histories": lambda: history_episodes(cfg, layout.release.manifest),
               "recoveries": lambda: recovery_episodes(cfg, layout.release.root)}
    datasets = {name: sources[name]() for name in DATASETS if not only or name in only}
    from pipeline.executors import make_executor
    from pipeline.runner import Runner

    console = Console()
    runner = Runner(make_executor(cfg.executor), console=console)
    failed = []
    for name, episodes in datasets.items():
        if name == "recoveries" and not episodes:
            console.print("[yellow]recoveries[/yellow]: no recovery demos (run `recover demos` first); skipped")
            continue
        try:
            frames = export_dataset(episodes, out / name, out / "_work" / name, size, runner,
                                    cfg.release.lerobot_render_quality)
        except FatalError as e:  # episodes set aside: the other datasets still go on
            failed.append(str(e))
            continue
        console.print(f"[green]{name}[/green]: {len(episodes)} episode(s), {frames} frames -> {out / name}")
    if failed:
        raise FatalError("\n".join(failed))
    return out
