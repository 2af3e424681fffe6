"""Videos rendered beside the physics: one render process per stage-1 worker.

The worker's physics loop hands every finished episode that needs videos (its logged
states and folder) to this process and goes on with the next episode while the frames are
drawn and encoded, so rendering leaves the physics' critical path: physics keeps one core,
the renderer (llvmpipe) the other.

Inputs: the worker's `SimEnv` (its compiled model is saved once per environment and
loaded by the render process, see pipeline/sim/state_render.py) and, per episode, a
ticket, the states, the folder and the video settings. Outputs: the same
`video_<camera>.mp4` and `frames.parquet` that `render_videos` writes, byte for byte, and
per ticket either the videos (camera -> file name) or an error text.

Invariants: tickets come back in submission order; the worker writes an episode's done
marker only after its videos came back, so a killed worker or render process leaves the
episode unmarked and it is redone on rerun. A render error fails that episode only; a dead
render process fails the episodes it held and a fresh one serves the next. The process
dies with its worker (PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import atexit
import multiprocessing as mp
import os
import queue as queue_mod
import tempfile
import traceback
from itertools import count
from pathlib import Path

import numpy as np

from pipeline.sim import SimEnv

# MJB files go to shared memory: 300 MB per LIBERO scene, read once by the render process
_MODEL_DIR = "/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir()

Result = tuple[str, dict[str, str] | None, str | None]  # ticket, videos, error


def sweep_orphaned_models(model_dir: str | Path = _MODEL_DIR) -> int:
    """Remove model files left by workers that are gone (killed before their render process read
    the queue): 300 MB each in shared memory, which an OOM kill would otherwise make worse."""
    removed = 0
    for p in Path(model_dir).glob("recover-render-*-*.mjb"):
        try:
            os.kill(int(p.name.split("-")[2]), 0)
        except ProcessLookupError:
            p.unlink(missing_ok=True)
            removed += 1
        except (ValueError, PermissionError):
            continue  # not our name pattern, or a live process of another user
    return removed


def _serve(jobs, results) -> None:
    """The render process: load models, render and encode episodes, in order."""
    from pipeline.executors.base import die_with_parent
    from pipeline.sim.state_render import StateRenderer
    from pipeline.stage1.video import frame_steps, write_videos

    die_with_parent()
    renderer: StateRenderer | None = None
    model_error: str | None = None
    while (msg := jobs.get()) is not None:
        if msg[0] == "model":
            _, path, size, quality = msg
            if renderer is not None:
                renderer.close()
            renderer, model_error = None, None
            try:
                renderer = StateRenderer(path)
                renderer.renderer(size, quality)  # textures upload while the physics runs
            except Exception:
                model_error = traceback.format_exc()
            finally:
                Path(path).unlink(missing_ok=True)
            continue
        _, ticket, fields, states, folder, cameras, fps, size, quality = msg
        try:
            if renderer is None:
                raise RuntimeError(f"render process has no model: {model_error}")
            steps = frame_steps(len(states) - 1, fps)
            frames = renderer.render_states(states[steps], cameras, size, quality, fields)
            results.put((ticket, write_videos(frames, steps, Path(folder), fps), None))
        except Exception:
            results.put((ticket, None, traceback.format_exc()))
    if renderer is not None:
        renderer.close()


class RenderProcess:
    """A render process fed in order; start it before building the environment (its spawn
    and imports, about 1 s, then overlap the build)."""

    def __init__(self):
        sweep_orphaned_models()
        ctx = mp.get_context("spawn")  # never fork a process holding EGL/MuJoCo state
        self._jobs, self._results = ctx.Queue(), ctx.Queue()
        self._proc = ctx.Process(target=_serve, args=(self._jobs, self._results), daemon=True)
        self._proc.start()
        self._model_key: tuple | None = None
        self._model_ref = None  # keeps the model alive so its id is not reused
        self._outstanding: list[str] = []
        self._names = count()
        atexit.register(self.close)  # a model file the process never loaded must not stay in /dev/shm

    @property
    def alive(self) -> bool:
        return self._proc.is_alive()

    def submit(self, ticket: str, env: SimEnv, states: np.ndarray, folder: Path, cameras: list[str], fps: int,
               size: int, quality: str) -> None:
        """Queue one episode's videos; `prepare` ran for this env (or runs now)."""
        self.prepare(env, size, quality)
        from pipeline.sim.state_render import reset_fields

        self._jobs.put(("render", ticket, reset_fields(env), states, str(folder), list(cameras), fps, size, quality))
        self._outstanding.append(ticket)

    def prepare(self, env: SimEnv, size: int, quality: str) -> None:
        """Send `env`'s model if the process does not have it yet (call before the physics)."""
        from pipeline.sim.state_render import save_model

        model = env.env.sim.model._model
        if self._model_key == (id(model), size, quality):
            return
        path = Path(_MODEL_DIR) / f"recover-render-{os.getpid()}-{next(self._names)}.mjb"
        save_model(env, path)
        self._jobs.put(("model", str(path), size, quality))
        self._model_key, self._model_ref = (id(model), size, quality), model

    def results(self, leave: int | None = None) -> list[Result]:
        """Finished tickets; with `leave`, block until at most that many are still out (0: all
        back), without it take only what is back already."""
        out: list[Result] = []
        while self._outstanding:
            wait = leave is not None and len(self._outstanding) > leave
            try:
                ticket, videos, error = self._results.get(timeout=1.0 if wait else 0.0)
            except queue_mod.Empty:
                if self.alive:
                    if wait:
                        continue
                    break
                try:  # it may have answered just before dying
                    ticket, videos, error = self._results.get(timeout=0.5)
                except queue_mod.Empty:
                    code = self._proc.exitcode
                    out += [(t, None, f"render process died (exit code {code})") for t in self._outstanding]
                    self._outstanding.clear()
                    break
            self._outstanding.remove(ticket)
            out.append((ticket, videos, error))
        return out

    def close(self) -> None:
        """Stop the process (after the jobs it has) and remove this worker's model files."""
        if self.alive:
            self._jobs.put(None)
            self._proc.join(timeout=10)
        if self._proc.is_alive():
            self._proc.kill()
        for p in Path(_MODEL_DIR).glob(f"recover-render-{os.getpid()}-*.mjb"):
            p.unlink(missing_ok=True)
