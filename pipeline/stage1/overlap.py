"""The render-overlap stream: physics in the worker, videos in its render process meanwhile.

A `RenderOverlapStage` runs each unit's physics in the worker (`simulate`), handing every
episode that needs videos to the worker's render process (`submit`, render_pool.py) and
going on with the next unit while the frames are drawn and encoded (one unit ahead at most,
so markers follow the physics closely). A unit is finished (the
runner writes its marker) only once all its videos are back, all before `stream` returns,
and on a fatal error too. A unit whose physics raises is set aside (`set_aside`); one whose
videos fail is set aside as `RenderError` (`render_failed`); a render process that died
fails the units it held and a fresh one serves the next. Users: stage 1 (one episode per
unit) and the recovery demonstrations (the successful tries of a scene, one video set each).
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from pipeline.config import VideoConfig
from pipeline.errors import FatalError
from pipeline.runner import Stage, UnitResult, WorkerContext

U = TypeVar("U")
Submit = Callable[[np.ndarray, Path], None]  # (states, folder): queue one episode's videos
Complete = Callable[[list[dict[str, str]]], UnitResult]  # videos of each submitted episode, in order


def render_process(ctx: WorkerContext):
    """The worker's render process, started on first use and restarted if it died."""
    from pipeline.stage1.render_pool import RenderProcess

    return ctx.helper("render", RenderProcess, alive=lambda r: r.alive)


@dataclass
class _Pending:
    unit: Any
    inputs: Any
    complete: Complete | None = None  # set once the unit's physics is done
    videos: list = field(default_factory=list)
    outstanding: int = 0
    error: str | None = None


class RenderOverlapStage(Stage[U]):
    @property
    @abstractmethod
    def video(self) -> VideoConfig:
        """The video settings (cameras, fps, resolution, quality)."""

    @property
    def renders_videos(self) -> bool:
        return self.video.render != "none"

    @abstractmethod
    def unit_env(self, unit: U, ctx: WorkerContext):
        """The unit's environment (from `ctx`), taken before its physics so the render
        process loads the model meanwhile."""

    @abstractmethod
    def simulate(self, unit: U, ctx: WorkerContext, env, submit: Submit) -> Complete:
        """Run the unit's physics, `submit` each episode that needs videos; return what makes
        the unit's result from their videos."""

    def process(self, unit: U, ctx: WorkerContext) -> UnitResult:
        results: list[UnitResult] = []
        self.stream([unit], ctx, lambda u, r: results.append(r))
        return results[0]

    def render_failed(self, unit: U, error: str) -> UnitResult:
        return UnitResult.set_aside("RenderError", error.strip().splitlines()[-1])

    def stream(self, units: list[U], ctx: WorkerContext, finish: Callable[[U, UnitResult], None]) -> None:
        v = self.video
        renders = render_process(ctx) if units and self.renders_videos else None  # spawns while the env builds
        pending: dict[str, _Pending] = {}
        tickets: dict[str, tuple[str, int]] = {}

        def settle(uid: str) -> None:
            p = pending[uid]
            if p.complete is None or p.outstanding:
                return
            del pending[uid]
            result = self.render_failed(p.unit, p.error) if p.error is not None else p.complete(p.videos)
            finish(p.unit, result.model_copy(update={"inputs": p.inputs}))

        def collect(leave: int | None) -> None:
            for ticket, videos, error in renders.results(leave) if renders is not None else []:
                uid, i = tickets.pop(ticket)
                p = pending.get(uid)
                if p is None:  # its unit failed after submitting; already set aside
                    continue
                p.outstanding -= 1
                p.videos[i] = videos
                if error is not None and p.error is None:
                    p.error = error
                settle(uid)

        try:
            for unit in units:
                ctx.emit(self.event("started", unit))
                uid = self.unit_id(unit)
                p = pending[uid] = _Pending(unit, self.fingerprint(unit))
                try:
                    env = self.unit_env(unit, ctx)
                    if renders is not None and not renders.alive:  # fail what it held, take a fresh one
                        collect(None)
                        renders = render_process(ctx)
                    if renders is not None:
                        renders.prepare(env, v.resolution, v.quality)  # model loads during the physics

                    def submit(states: np.ndarray, folder: Path, p=p, uid=uid, env=env) -> None:
                        ticket = f"{uid}#{len(p.videos)}"
                        tickets[ticket] = (uid, len(p.videos))
                        p.videos.append(None)
                        p.outstanding += 1
                        renders.submit(ticket, env, states, folder, list(v.cameras), v.fps, v.resolution, v.quality)

                    complete = self.simulate(unit, ctx, env, submit)
                except FatalError:
                    raise
                except Exception as e:  # one unit's failure must not cost the others
                    pending.pop(uid)
                    result = self.set_aside(unit, e)
                    if result is None:
                        raise
                    finish(unit, result.model_copy(update={"inputs": p.inputs}))
                    continue
                p.complete = complete
                settle(uid)
                # the next unit's physics overlaps this unit's videos, no more: a renderer slower
                # than the physics would otherwise hold every marker (and each unit's states)
                # back until the shard ends, and a kill would lose all that work
                collect(leave=p.outstanding)
        finally:
            collect(leave=0)  # also on a fatal error: finished videos still get their markers
