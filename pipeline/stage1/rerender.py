"""`recover stage1 --rerender`: redraw an existing run's frames from its logged states.

Frames made by an older renderer (pipeline/rendered.py) are redrawn with the current one
without re-running any physics: the stage-1 videos and frame tables of every rendered
episode (same cameras, fps and size as before, at `stage1.video.quality`), and the
pre-failure history frames of stage 2's scenes and of the release (re-rendered from the
sim states of their `_history.npz` sibling, at the size they had).

A `Stage` on the run's executor: one unit per episode or history archive, units of one
task on one worker (one environment build). A unit's last write is the stamped frame
table (or archive), so an interrupted unit is still stale and the next run redoes it;
what is current is skipped, so a rerun finishes the rest and a third does nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.config import Config
from pipeline.layout import SCENE_GLOB, EpisodeFiles, RunLayout, parse_key, parse_scene_bddl, scene_files
from pipeline.records import read_episodes
from pipeline.rendered import KEY, history_version, stale_frames
from pipeline.runner import Stage, UnitResult, WorkerContext
from pipeline.sim.render import RENDERER_VERSION

@dataclass(frozen=True)
class RerenderUnit:
    kind: str  # "videos" | "history"
    suite: str
    task: str
    path: str  # the episode folder, or the history-frames archive
    source: str  # the states it is drawn from: the episode's states.npy, or the scene's `_history.npz`
    cameras: tuple[str, ...] = ()
    fps: int = 0
    size: int = 0

    @property
    def unit_id(self) -> str:
        return f"{self.kind}:{self.path}"


def video_units(cfg: Config) -> list[RerenderUnit]:
    stage1 = RunLayout.of(cfg).stage1
    if not stage1.manifest.is_file():
        return []
    out = []
    for rec in read_episodes(stage1.manifest):
        files = stage1.episode(rec)
        if rec.videos and stale_frames([files.frames]):
            size = _video_size(stage1.video(rec, next(iter(rec.videos))))
            out.append(RerenderUnit("videos", rec.suite, rec.task, str(files.dir), str(files.states), tuple(rec.videos),
                                    rec.video_fps or cfg.stage1.video.fps, size or cfg.stage1.video.resolution))
    return out


def history_units(cfg: Config) -> list[RerenderUnit]:
    layout = RunLayout.of(cfg)
    out = []
    for root in map(Path, dict.fromkeys((layout.stage2.root, layout.release.root))):
        for bddl in sorted(root.glob(SCENE_GLOB)) if root.is_dir() else []:
            scene = parse_scene_bddl(bddl.relative_to(root).as_posix())
            files = scene_files(root, *scene) if scene else None
            if files is None or not files.history_frames.is_file():
                continue
            with np.load(files.history_frames) as z:
                if history_version(z) == RENDERER_VERSION:
                    continue
                cams = tuple(k for k in z.files if k not in ("steps", KEY))
                size = int(z[cams[0]].shape[1]) if cams and z[cams[0]].ndim == 4 else 0
            suite, task, _ = parse_key(scene[0])
            out.append(RerenderUnit("history", suite, task, str(files.history_frames), str(files.history), cams, 0, size))
    return out


def _video_size(path: Path | None) -> int:
    import av

    if path is None or not path.is_file():
        return 0
    try:
        with av.open(str(path)) as c:
            return int(c.streams.video[0].height)
    except (av.FFmpegError, OSError, IndexError):  # unreadable: redrawn at the configured size
        return 0


@dataclass
class Rerender(Stage[RerenderUnit]):
    cfg: Config
    planned: list[RerenderUnit]
    name: str = "re-render"

    @property
    def root(self) -> Path:
        return RunLayout.of(self.cfg).stage1.rerender

    def units(self, cfg=None) -> list[RerenderUnit]:
        return self.planned

    def unit_id(self, unit: RerenderUnit) -> str:
        return unit.unit_id

    def marker_id(self, unit: RerenderUnit) -> str:
        import hashlib

        return hashlib.sha256(unit.unit_id.encode()).hexdigest()[:24]

    def fingerprint(self, unit: RerenderUnit):
        # the stale file as it is now: a file made stale again later (an older checkout) differs
        target = EpisodeFiles(Path(unit.path)).frames if unit.kind == "videos" else Path(unit.path)
        st = target.stat() if target.exists() else None
        return {"renderer_version": RENDERER_VERSION, "stale": f"{st.st_size}:{st.st_mtime_ns}" if st else None}

    def group(self, unit: RerenderUnit):
        return (unit.suite, unit.task)

    def process(self, unit: RerenderUnit, ctx: WorkerContext) -> UnitResult:
        from pipeline.sim.registry import get_task

        env = ctx.env(get_task(unit.suite, unit.task))
        if unit.kind == "videos":
            from pipeline.stage1.video import render_videos

            states = np.load(unit.source)
            render_videos(env, states, unit.path, list(unit.cameras), unit.fps, unit.size, self.cfg.stage1.video.quality)
        else:
            from pipeline.stage2.history import render_frames, write_history

            with np.load(unit.source) as z:
                history = {k: z[k] for k in ("steps", "sim_states")}
            write_history(Path(unit.path), render_frames(env, history, list(unit.cameras), unit.size))
        return UnitResult(ok=True)

    def set_aside(self, unit: RerenderUnit, error: Exception) -> UnitResult:
        return UnitResult.set_aside(type(error).__name__, f"{unit.path}: {error}")


def run(cfg: Config) -> int:
    """Re-render every stale frame file of the run; return how many units were redrawn."""
    from rich.console import Console

    from pipeline.errors import FatalError
    from pipeline.executors import make_executor
    from pipeline.runner import Runner

    console = Console()
    units = video_units(cfg) + history_units(cfg)
    if not units:
        console.print(f"re-render: every frame of {cfg.out} is already from renderer version {RENDERER_VERSION}; "
                      "nothing to do")
        return 0
    stage = Rerender(cfg, units)
    runner = Runner(make_executor(cfg.executor), console=console)
    todo = runner.pending(stage, units)
    stats = runner.execute(stage, todo, done_before=len(units) - len(todo))
    if stats.set_aside:
        raise FatalError(f"re-render: {len(stats.set_aside)} unit(s) set aside (rerun to retry them): " + "; ".join(
            f"{ev.unit}: {ev.reason}: {(ev.detail or '').strip()[:200]}" for ev in stats.set_aside))
    n_video = sum(u.kind == "videos" for u in units)
    console.print(f"re-render: {n_video} episode video set(s) and {len(units) - n_video} history archive(s) of "
                  f"{cfg.out} now from renderer version {RENDERER_VERSION}")
    return len(units)
