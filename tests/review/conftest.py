"""Fixtures of the review tests: a tiny real run folder, a real queue database, people, a server.

Every test that uses `engine` (or `db_url`) runs twice: on SQLite (the default) and on a real
PostgreSQL server (`tests/pg_cluster.py`: one throwaway cluster per test process, a fresh
database per test). What is SQLite-only by nature (the 0600 database file) makes its own
SQLite engine instead."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.records import Category, Characterization, Level
from pipeline.review.auth import add_user
from pipeline.review.db import make_engine, write_session
from pipeline.review.enqueue import enqueue
from pipeline.review.workflow import QueueSettings
from pipeline.stage3.inputs import collect, context
from pipeline.stage3.run import proposal_for
from tests.review.sample_run import INSTRUCTION, build

ACTION = "Set the black bowl upright, then place it on the plate"


def fill_queue(run_dir: Path, engine, required: int = 2, model: str | None = None) -> list[int]:
    """Enqueue every stage-2 outcome of `run_dir` with a fixed characterization; return item ids."""
    ids = []
    for unit in collect(run_dir):
        ch = None
        if unit.localization is not None:
            ch = Characterization(key=unit.key, recovery_level=Level.L3, failure_category=Category.object_displacement,
                                  recovery_action=ACTION, source="simstate", model=model)
        q = unit.quarantine
        with write_session(engine) as s:
            item, _ = enqueue(s, key=unit.key, instruction=unit.localization.instruction if unit.localization else INSTRUCTION,
                              proposal=proposal_for(unit, ch, q), context=context(run_dir, unit, 20, 10.0),
                              required_reviews=required, quarantined=q is not None,
                              reason=f"{q.stage}:{q.reason}" if q else None)
            ids.append(item.id)
    return ids


@pytest.fixture(scope="session")
def sample_media(tmp_path_factory) -> Path:
    """Built once: the media and stage-2 files of 5 localized + 1 quarantined episodes."""
    root = tmp_path_factory.mktemp("sample_run")
    build(root, n_episodes=5, n_quarantined=1)
    return root


@pytest.fixture
def run_dir(tmp_path, sample_media) -> Path:
    import shutil

    dst = tmp_path / "run"
    shutil.copytree(sample_media, dst)
    return dst


@pytest.fixture
def settings() -> QueueSettings:
    return QueueSettings(required_reviews=2, time_tolerance_s=0.5, lease_seconds=600)


@pytest.fixture(scope="session")
def pg_cluster():
    from tests.pg_cluster import PgCluster

    with PgCluster() as pg:
        yield pg


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, run_dir) -> str:
    if request.param == "sqlite":
        yield f"sqlite:///{run_dir / 'stage3' / 'review.sqlite'}"
        return
    pg = request.getfixturevalue("pg_cluster")
    url = pg.new_database()
    yield url
    pg.drop_database(url)


@pytest.fixture
def engine(db_url):
    eng = make_engine(db_url)
    yield eng
    eng.dispose()


@pytest.fixture
def people(engine) -> dict[str, str]:
    """name -> personal token."""
    return {
        "ann": add_user(engine, "ann", "reviewer"),
        "bob": add_user(engine, "bob", "reviewer"),
        "cat": add_user(engine, "cat", "reviewer"),
        "dan": add_user(engine, "dan", "adjudicator"),
        "eve": add_user(engine, "eve", "admin"),
    }


@pytest.fixture
def items(run_dir, engine) -> list[int]:
    return fill_queue(run_dir, engine)


@pytest.fixture
def server(run_dir, engine, settings, people, items):
    from pipeline.review.api import create_app
    from pipeline.review.server import ThreadedServer

    with ThreadedServer(create_app(run_dir, engine, settings)) as srv:
        yield srv
