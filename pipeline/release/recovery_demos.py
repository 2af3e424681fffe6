"""`recover demos`: recovery demonstrations, successful recovery-expert rollouts from the released train scenes.

Inputs: the release manifest (`<release>/scenarios.parquet`, its scene files) and
`cfg.release` (`recovery_demos` per scene, `recovery_demo_tries`, `recovery_demo_variation`,
`certify_horizon`), `cfg.stage1.video` for the videos.
Outputs under `<run>/recoveries/` (`RunLayout.recoveries`):
    episodes/<suite>/<task>/<episode_id>/step_<NNNN>/demo_<k>/
        states.npy, actions.npy, steps.parquet  as stage 1 writes them (`EpisodeRecorder`)
        video_<camera>.mp4, frames.parquet as stage 1 renders them (its render process)
    demos.parquet      one row per demo (`DemoRecord`: scene id, level, category, seed, ...)
    scenes.jsonl       one line per scene: tries, demos, why the other tries failed,
                       `unreplayable` (successful tries dropped for not replaying)
    _done/<scene>.done the scene's line, written after all its demos' videos are back
Only scenes of the train split (`scenarios.parquet`'s `split`, `pipeline.release.split`) are
recorded: the eval scenes stay held out for `recover eval`. Try k of a scene runs the recovery expert with seed `demo_seed(run seed, scene id, k)` and
the configured variation (approach and speed); a try that does not reach the goal is no
demo: it is counted (with the expert's reason) and its files are not kept. A successful try
is kept only if it replays: its float64 actions, stepped by robosuite's own `env.step` from
the dataset card's restore (`pipeline.release.replay.check_demo`), must give its states bit
for bit and reach the goal at its last step; a try that does not is dropped and counted
(`unreplayable` in scenes.jsonl; expected 0). Tries stop at `recovery_demos` kept demos or
`recovery_demo_tries` tries. The scenes run as a Stage
(`DemoStage`, one unit per scene, stage 1's render-overlap stream: `pipeline.stage1.overlap`)
by the `Runner` on the configured executor; resumable per scene; a scene whose environment,
state or videos fail is set aside with the reason (`errors/<scene>.txt`) and the rest goes on.
Nothing in `recover eval` reads these: they are training data.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
import traceback
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import BaseModel, ConfigDict, ValidationError
from rich.console import Console

from pipeline import SCHEMA_VERSION
from pipeline.atomic import write_text, write_with
from pipeline.config import Config, VideoConfig
from pipeline.errors import FatalError
from pipeline.layout import RecoveriesLayout, RunLayout, episode_key, scene_unit
from pipeline.layout import scene_id as layout_scene_id
from pipeline.release.experts import attempt, recovery_expert
from pipeline.release.manifest import MANIFEST_NAME, ScenarioRow, read_manifest
from pipeline.release.replay import check_demo
from pipeline.release.scene_physics import restore_scene, scene_task
from pipeline.runner import UnitResult, WorkerContext
from pipeline.stage1.overlap import Complete, RenderOverlapStage, Submit
from pipeline.stage1.recorder import EpisodeRecorder

if TYPE_CHECKING:
    from pipeline.executors import Executor

def scene_id(row: ScenarioRow) -> str:
    """The eval's scene id (`pipeline.eval.scenes`): stable across copies of the release."""
    return layout_scene_id(episode_key(row.suite, row.task, row.episode_id), row.step)


def demo_seed(seed: int, scene: str, k: int) -> int:
    digest = hashlib.sha256(f"recovery-demo/{seed}/{scene}/{k}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


class DemoRecord(BaseModel):
    model_config = ConfigDict(extra="forbid")

    scene_id: str
    suite: str
    task: str
    instruction: str
    episode_id: str  # the failed stage-1 episode the scene was cut from
    step: int  # the scene's step in it
    level: str
    category: str
    demo_index: int  # k-th demo of the scene
    try_index: int  # which try produced it (earlier tries failed)
    seed: int
    variation: float
    steps: int
    state_dim: int
    path: str  # relative to the recoveries folder
    videos: dict[str, str] = {}
    video_fps: int | None = None
    wall_time_s: float


DEMO_SCHEMA = pa.schema(
    [
        pa.field("scene_id", pa.string(), nullable=False),
        pa.field("suite", pa.string(), nullable=False),
        pa.field("task", pa.string(), nullable=False),
        pa.field("instruction", pa.string(), nullable=False),
        pa.field("episode_id", pa.string(), nullable=False),
        pa.field("step", pa.int32(), nullable=False),
        pa.field("level", pa.string(), nullable=False),
        pa.field("category", pa.string(), nullable=False),
        pa.field("demo_index", pa.int32(), nullable=False),
        pa.field("try_index", pa.int32(), nullable=False),
        pa.field("seed", pa.int64(), nullable=False),
        pa.field("variation", pa.float64(), nullable=False),
        pa.field("steps", pa.int32(), nullable=False),
        pa.field("state_dim", pa.int32(), nullable=False),
        pa.field("path", pa.string(), nullable=False),
        pa.field("videos", pa.map_(pa.string(), pa.string()), nullable=False),
        pa.field("video_fps", pa.int32()),
        pa.field("wall_time_s", pa.float64(), nullable=False),
    ],
    metadata={"schema_version": str(SCHEMA_VERSION), "name": "libero-recover recovery demonstrations"},
)


def write_demos(path: Path, demos: list[DemoRecord]) -> None:
    demos = sorted(demos, key=lambda d: (d.scene_id, d.demo_index))
    cols = {f.name: [getattr(d, f.name) for d in demos] for f in DEMO_SCHEMA}
    cols["videos"] = [list(v.items()) for v in cols["videos"]]
    table = pa.table(cols, schema=DEMO_SCHEMA)
    write_with(path, lambda p: pq.write_table(table, p))


def read_demos(path: Path) -> list[DemoRecord]:
    """Demo records of `demos.parquet`; ValueError naming the file and row if it is not one."""
    try:
        rows = pq.read_table(path).to_pylist()
    except (OSError, pa.ArrowInvalid) as e:
        raise ValueError(f"{path}: not a readable demos table: {e}") from None
    out = []
    for i, r in enumerate(rows):
        r["videos"] = dict(r["videos"] or [])
        try:
            out.append(DemoRecord.model_validate(r))
        except ValidationError as e:
            raise ValueError(f"{path}: row {i} invalid: {e}") from None
    return out


def train_rows(rows: list[ScenarioRow]) -> list[ScenarioRow]:
    """The scenes demonstrations are recorded on: the train split (`pipeline.release.split`),
    so the eval scenes stay held out; a release built before the split has none, all of it."""
    if all(r.split is None for r in rows):
        return list(rows)
    return [r for r in rows if r.split == "train"]


def _unit(row: ScenarioRow) -> str:
    return scene_unit(episode_key(row.suite, row.task, row.episode_id), row.step)


def _record_scene(env, row: ScenarioRow, state: np.ndarray, cfg: Config, root: Path,
                  submit: Callable[[DemoRecord, np.ndarray], None]) -> dict:
    """Run the tries of one scene; hand each demo to `submit(record, states)`; return its summary."""
    rc = cfg.release
    sid = scene_id(row)
    base = RecoveriesLayout(root).scene_dir(episode_key(row.suite, row.task, row.episode_id), row.step)
    if base.exists():  # leftovers of a scene killed before its marker
        shutil.rmtree(base)
    fails: Counter[str] = Counter()
    demos = tries = unreplayable = 0
    while demos < rc.recovery_demos and tries < rc.recovery_demo_tries:
        seed = demo_seed(cfg.run.seed, sid, tries)
        t0 = time.perf_counter()
        restore_scene(env, state)
        rec = EpisodeRecorder(env)
        policy = recovery_expert(env, seed=seed, variation=rc.recovery_demo_variation)
        out = attempt(env, state, policy, seed, rc.certify_horizon, cfg.stage1.rollout.chunk_size,
                      on_step=rec.on_step, restore=False)
        policy.close()
        tries += 1
        if not out.success:
            fails[out.reason or "unknown"] += 1
            continue
        folder = base / f"demo_{demos}"
        rec.write(folder)
        _, problems = check_demo(env, state, folder, out.steps)  # plain LIBERO, from the card's restore
        if problems:
            unreplayable += 1
            shutil.rmtree(folder)
            continue
        record = DemoRecord(
            scene_id=sid, suite=row.suite, task=row.task, instruction=row.instruction, episode_id=row.episode_id,
            step=row.step, level=row.level, category=row.category, demo_index=demos, try_index=tries - 1,
            seed=seed, variation=rc.recovery_demo_variation, steps=out.steps, state_dim=env.state_dim,
            path=folder.relative_to(root).as_posix(), wall_time_s=round(time.perf_counter() - t0, 4))
        submit(record, rec.states_array())
        demos += 1
    return {"scene_id": sid, "level": row.level, "category": row.category, "tries": tries, "demos": demos,
            "unreplayable": unreplayable, "failed": dict(sorted(fails.items()))}


@dataclass
class DemoStage(RenderOverlapStage[ScenarioRow]):
    """One unit per released scene: its tries here, each demo's videos in the worker's render
    process meanwhile (stage 1's render-overlap stream); the marker holds the scene's summary
    and its demos' records, written once every video is back."""

    cfg: Config
    rows: list[ScenarioRow]
    name: str = "recovery demos"

    @property
    def root(self) -> Path:
        return RunLayout.of(self.cfg).recoveries.root

    @property
    def release(self) -> Path:
        from pipeline.release.build import release_dir

        return release_dir(self.cfg)

    @property
    def video(self) -> VideoConfig:
        return self.cfg.stage1.video

    @property
    def renders_videos(self) -> bool:
        return True  # demos are training data: always with their videos

    def units(self, cfg: Config) -> list[ScenarioRow]:
        return list(self.rows) if cfg.release.recovery_demos else []

    def unit_id(self, row: ScenarioRow) -> str:
        return _unit(row)

    def group(self, row: ScenarioRow):
        return row.suite, row.task, row.bddl_sha256  # one model (task, BDDL) per shard

    def unit_env(self, row: ScenarioRow, ctx: WorkerContext):
        return ctx.env(scene_task(row.suite, row.task, row.instruction, self.release / row.bddl_path))

    def simulate(self, row: ScenarioRow, ctx: WorkerContext, env, submit: Submit) -> Complete:
        root, records = self.root, []
        state = np.load(self.release / row.state_path, allow_pickle=False)

        def demo(record: DemoRecord, states: np.ndarray) -> None:
            records.append(record)
            submit(states, root / record.path)

        summary = _record_scene(env, row, state, self.cfg, root, demo)

        def complete(videos: list[dict[str, str]]) -> UnitResult:
            fps = self.video.fps
            done = [r.model_copy(update={"videos": v, "video_fps": fps}) for r, v in zip(records, videos, strict=True)]
            info = {**summary, "records": [r.model_dump(mode="json") for r in done]}
            return UnitResult(info=info, ok=summary["demos"] > 0, status=f"{summary['demos']} demo(s)")

        return complete

    def set_aside(self, row: ScenarioRow, error: Exception) -> UnitResult:
        write_text(RecoveriesLayout(self.root).error(self.unit_id(row)), traceback.format_exc())
        return UnitResult.set_aside(type(error).__name__, str(error))

    def render_failed(self, row: ScenarioRow, error: str) -> UnitResult:
        write_text(RecoveriesLayout(self.root).error(self.unit_id(row)), error)
        return UnitResult.set_aside("RenderError", error.strip().splitlines()[-1])

    def worker_died(self, row: ScenarioRow, reason: str) -> None:
        write_text(RecoveriesLayout(self.root).error(self.unit_id(row)), f"worker died: {reason}\n")

    def after_done(self, row: ScenarioRow, result: UnitResult) -> None:
        RecoveriesLayout(self.root).error(self.unit_id(row)).unlink(missing_ok=True)


def run(cfg: Config, console: Console | None = None, executor: Executor | None = None) -> Path:
    from pipeline.executors import make_executor
    from pipeline.release.build import release_dir
    from pipeline.runner import Runner
    from pipeline.stage1.run import WORKER_ENV

    console = console or Console()
    release = release_dir(cfg)
    try:
        rows = read_manifest(release / MANIFEST_NAME)
    except FileNotFoundError:
        raise FatalError(f"{release / MANIFEST_NAME}: no release to record demos from; run `recover release` first") from None
    except ValueError as e:
        raise FatalError(str(e)) from None
    released = len(rows)
    rows = train_rows(rows)
    console.print(f"recording on the {len(rows)} train scene(s) of {released} released (release.split)")
    stage = DemoStage(cfg, rows)
    root = stage.root
    Runner(executor or make_executor(cfg.executor, worker_env=WORKER_ENV), console=console).run(stage, cfg)
    from pipeline.runner.runner import finished

    summaries = list(finished(stage, rows).values())
    demos = [DemoRecord.model_validate(d) for s in summaries for d in s.get("records", [])]
    write_demos(RecoveriesLayout(root).demos, demos)
    # `unreplayable`: absent from markers written before demos were replayed
    lines = [{**{k: s[k] for k in ("scene_id", "level", "category", "tries", "demos", "failed")},
              "unreplayable": s.get("unreplayable", 0)} for s in summaries]
    write_text(RecoveriesLayout(root).scenes_log, "".join(json.dumps(x, sort_keys=True) + "\n" for x in
                                            sorted(lines, key=lambda x: x["scene_id"])))
    tries = sum(x["tries"] for x in lines)
    dropped = sum(x["unreplayable"] for x in lines)
    failed = tries - len(demos) - dropped
    console.print(f"[green]{len(demos)} recovery demo(s)[/green] from {sum(x['demos'] > 0 for x in lines)} of "
                  f"{len(rows)} scene(s); {failed} unsuccessful tr{'y' if failed == 1 else 'ies'} not kept; "
                  f"{dropped} dropped for not replaying in plain LIBERO -> {root}")
    return root
