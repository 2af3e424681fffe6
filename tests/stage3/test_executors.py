"""Stage 3 is a real stage: the stage object pickles, and two local workers (each with its
own review-database engine and characterizer) fill the same SQLite queue with the same
items, files and markers as the inline executor."""

from __future__ import annotations

import io
import json
import pickle
from pathlib import Path

import pytest
from rich.console import Console
from sqlalchemy import select

from pipeline.config import Config
from pipeline.executors import make_executor
from pipeline.review.db import Item, make_engine, read_session
from pipeline.review.server import engine_for
from pipeline.runner import Runner
from pipeline.stage3.run import Stage3
from tests.review.sample_run import SUITE, TASK, build


REPO = Path(__file__).resolve().parents[2]


def _stage3(tmp_path: Path, kind: str) -> Path:
    run = tmp_path / kind
    build(run, n_episodes=4, n_quarantined=1, wrist=False)
    (run / "stage2" / "evidence" / SUITE / TASK / "scripted-i03-s0.parquet").unlink()  # characterization fails
    cfg = Config.model_validate({"run": {"output_dir": str(run)}, "stage3": {"reviews_per_item": 2},
                                 "executor": {"kind": kind, "workers": 2}})
    engine_for(cfg).dispose()  # as `stage3.run` does: the schema exists before the workers open it
    stage = pickle.loads(pickle.dumps(Stage3(cfg, batch_size=2)))
    units = stage.units(cfg)
    assert len(stage.shards(units, 2)) == 3  # more shards than workers: both workers take some
    executor = make_executor(cfg.executor, worker_env={"PYTHONPATH": str(REPO)})  # Ray workers import `pipeline`
    stats = Runner(executor, console=Console(file=io.StringIO())).run(stage, cfg)
    assert stats.ran == 5 and not stats.set_aside and not stats.report.retried
    return run


def _outcome(run: Path) -> dict:
    """Items, files and markers, with the run folder's own path and the inputs' mtimes left out."""
    with read_session(make_engine(f"sqlite:///{run / 'stage3' / 'review.sqlite'}")) as s:
        items = {i.episode_id: (i.status, i.revision, i.quarantined, i.quarantine_reason, i.quarantine_detail,
                                json.dumps(i.proposal, sort_keys=True), json.dumps(i.context, sort_keys=True))
                 for i in s.scalars(select(Item))}
    files = {p.relative_to(run).as_posix(): p.read_text() for sub in ("characterizations", "quarantine")
             for p in sorted((run / "stage3" / sub).rglob("*.json"))}
    markers = {p.name: {k: v for k, v in json.loads(p.read_text()).items() if k != "inputs"}
               for p in (run / "stage3" / "_done").glob("*.done")}
    return json.loads(json.dumps({"items": items, "files": files, "markers": markers}).replace(str(run), "<run>"))


def test_stage3_pickles_and_two_local_workers_fill_the_queue_as_inline_does(tmp_path):
    inline, local = _outcome(_stage3(tmp_path, "inline")), _outcome(_stage3(tmp_path, "local"))
    assert len(inline["items"]) == 5 and sum(not i[2] for i in inline["items"].values()) == 3
    assert len(inline["markers"]) == 5
    assert local == inline


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time (tests/executors/test_ray.py)
def test_stage3_on_two_ray_workers_fills_the_queue_as_inline_does(tmp_path):
    assert _outcome(_stage3(tmp_path, "ray")) == _outcome(_stage3(tmp_path, "inline"))
