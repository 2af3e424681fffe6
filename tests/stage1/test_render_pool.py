"""Videos from the worker's render process are the in-process videos, byte for byte, and an
episode whose videos never came back gets no done marker.

Both cameras byte for byte: stage 1's encoder is repeatable (`pipeline.h264`). With the
encoder before (one thread, x264's mb-tree on) the 64 px wrist videos here differed between
two runs of the same code."""

from __future__ import annotations

import os

import numpy as np
import pytest

from pipeline.atomic import Completions
from pipeline.config import Config
from pipeline.runner import WorkerContext
from pipeline.runner.runner import run_shard
from pipeline.sim import get_task
from pipeline.stage1.render_pool import RenderProcess
from pipeline.stage1.stage import Stage1
from pipeline.stage1.units import plan_units
from pipeline.stage1.worker import run_one
from toy_policy import DriftPolicy, make

CAMERAS = ["agentview", "robot0_eye_in_hand"]


def _cfg(tmp_path, init_states=(4,)) -> Config:
    return Config.model_validate({
        "run": {"output_dir": str(tmp_path), "seed": 1},
        "tasks": {"suites": ["libero_spatial"], "max_tasks_per_suite": 1, "init_states": list(init_states)},
        "stage1": {
            "policy": {"name": "drift"},
            "rollout": {"horizon": 13, "chunk_size": 4, "settle_steps": 3},
            "video": {"cameras": CAMERAS, "fps": 5, "resolution": 64, "render": "all", "quality": "fast"},
        },
    })


@pytest.fixture
def events():
    return []


@pytest.fixture
def ctx(events):
    """This (pytest) process as a worker: run_shard starts a render process here; closing the
    context stops it after each test, so no other test mistakes it for one of its workers."""
    c = WorkerContext(events.append)
    yield c
    c.close()


def _shard(cfg: Config, units) -> tuple[Stage1, tuple]:
    stage = Stage1(cfg, make)
    (shard,) = stage.shards(units, workers=1)
    return stage, shard


def _outcomes(events) -> list[str]:
    return [e.kind for e in events if e.kind != "started"]


def _files(folder) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.mark.sim
def test_render_process_writes_the_same_bytes_as_rendering_in_the_worker(tmp_path, ctx, events):
    cfg = _cfg(tmp_path, init_states=(4, 5))
    units = plan_units(cfg)
    inline = tmp_path / "inline"
    for u in units:  # the in-process path on the worker's own (cached) environment
        run_one(ctx.env(get_task(u.suite, u.task)), DriftPolicy(), u, cfg, inline)
    stage1 = tmp_path / "stage1"
    assert run_shard(_shard(cfg, units), ctx) == 2
    done = Completions(stage1)
    for u in units:
        ours = _files(stage1 / u.rel_dir)
        assert set(ours) == {"actions.npy", "states.npy", "steps.parquet", "frames.parquet", *(f"video_{c}.mp4" for c in CAMERAS)}
        theirs = _files(inline / u.rel_dir)
        assert ours == theirs
        assert done.is_done(u.unit_id)
    assert _outcomes(events) == ["done", "done"] and ctx.env_builds == 1  # one env for both paths


@pytest.mark.sim
def test_an_episode_whose_render_process_died_is_left_unmarked_redone_on_rerun_and_the_next_is_served(
        tmp_path, monkeypatch, ctx, events):
    cfg = _cfg(tmp_path, init_states=(4, 5))
    units = plan_units(cfg)
    stage1 = tmp_path / "stage1"
    submit = RenderProcess.submit
    killed = []

    def submit_then_die(self, ticket, *a, **kw):
        submit(self, ticket, *a, **kw)
        if not killed:  # the first episode's renderer dies before answering
            killed.append(ticket)
            self._proc.kill()
            self._proc.join()

    monkeypatch.setattr(RenderProcess, "submit", submit_then_die)
    job = _shard(cfg, units)
    run_shard(job, ctx)
    done = Completions(stage1)
    first, second = units
    assert killed == [f"{first.unit_id}#0"] and not done.is_done(first.unit_id)  # ticket: unit # video set
    assert (stage1 / "errors" / f"{first.unit_id}.txt").read_text().startswith("render process died")
    assert done.is_done(second.unit_id)  # a fresh render process took the next episode
    assert np.load(stage1 / second.rel_dir / "states.npy").shape[0] == 14
    assert sorted(_outcomes(events)) == ["done", "set_aside"]
    assert [e.reason for e in events if e.kind == "set_aside"] == ["RenderError"]
    # the rerun redoes the unmarked episode only, videos included
    assert run_shard(job, ctx) == 1
    assert done.is_done(first.unit_id) and (stage1 / first.rel_dir / "video_agentview.mp4").exists()


def test_model_files_of_dead_workers_are_swept_and_live_ones_kept(tmp_path):
    import subprocess

    from pipeline.stage1.render_pool import sweep_orphaned_models

    gone = subprocess.Popen(["true"])
    gone.wait()
    dead = tmp_path / f"recover-render-{gone.pid}-0.mjb"
    live = tmp_path / f"recover-render-{os.getpid()}-0.mjb"
    other = tmp_path / "recover-render-notapid-0.mjb"
    for p in (dead, live, other):
        p.write_bytes(b"x")
    assert sweep_orphaned_models(tmp_path) == 1
    assert not dead.exists() and live.exists() and other.exists()


@pytest.mark.sim
def test_physics_runs_at_most_one_episode_ahead_of_a_slow_render_process(tmp_path, monkeypatch, ctx, events):
    """A renderer slower than the physics (here: nothing is ever back at a glance) must not hold
    every marker back to the shard's end: a kill then would lose all the shard's work."""
    cfg = _cfg(tmp_path, init_states=(4, 5, 6))
    units = plan_units(cfg)
    results = RenderProcess.results
    monkeypatch.setattr(RenderProcess, "results",
                        lambda self, leave=None: [] if leave is None else results(self, leave))
    assert run_shard(_shard(cfg, units), ctx) == 3
    order = [(e.kind, e.unit) for e in events]
    first, _, third = (u.unit_id for u in units)
    assert order.index(("done", first)) < order.index(("started", third))
    assert order[-1] == ("done", third)
