"""Building and running the review server from a run config.

Inputs: the validated `Config` (run folder, `stage3` section).
Outputs: the engine, the app; `serve` blocks running uvicorn (one process, or N worker
processes that each build the app from the config file: `app_from_env`); `ThreadedServer`
runs it in a background thread on loopback (tests) and stops it cleanly.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from pathlib import Path

from sqlalchemy.engine import Engine

from pipeline.config import Config
from pipeline.review.db import default_url, make_engine
from pipeline.review.workflow import QueueSettings


def db_url(cfg: Config) -> str:
    return cfg.stage3.db_url or default_url(cfg.out)


def settings(cfg: Config) -> QueueSettings:
    s = cfg.stage3
    return QueueSettings(required_reviews=s.reviews_per_item, time_tolerance_s=s.time_tolerance_s,
                         lease_seconds=s.lease_seconds, control_hz=cfg.stage1.rollout.control_hz,
                         max_leases=s.max_leases_per_person, lease_max_s=max(s.lease_max_seconds, s.lease_seconds))


def engine_for(cfg: Config) -> Engine:
    return make_engine(db_url(cfg))


def build_app(cfg: Config, engine: Engine | None = None, docs: bool = False):
    from pipeline.review.api import create_app

    return create_app(Path(cfg.out), engine or engine_for(cfg), settings(cfg), docs=docs)


CONFIG_ENV = "RECOVER_REVIEW_CONFIG"  # the config file worker processes build their app from
DOCS_ENV = "RECOVER_REVIEW_DOCS"


def app_from_env():
    """uvicorn's app factory in each worker process (`--workers N`)."""
    from pipeline.config import load_config

    return build_app(load_config(Path(os.environ[CONFIG_ENV])), docs=os.environ.get(DOCS_ENV) == "1")


def serve(config_path: Path, cfg: Config, host: str, port: int, workers: int = 1, docs: bool = False) -> None:
    """Serve until interrupted. Several processes share the port (uvicorn's supervisor) and
    the database; each write is one transaction of the service layer (SQLite's write lock, or
    the item's row lock on PostgreSQL), so decisions are neither lost nor double-counted
    whichever process takes them."""
    import uvicorn

    from pipeline.review.limits import BoundedHttpProtocol

    # the header deadline and size cap live in the protocol (limits.py); the rest in the app
    bounded = {"http": BoundedHttpProtocol}
    if workers <= 1:
        uvicorn.run(build_app(cfg, docs=docs), host=host, port=port, log_level="info", **bounded)
        return
    engine_for(cfg).dispose()  # migrate the schema once, before the workers start
    os.environ[CONFIG_ENV], os.environ[DOCS_ENV] = str(Path(config_path).resolve()), "1" if docs else "0"
    uvicorn.run("pipeline.review.server:app_from_env", factory=True, host=host, port=port, workers=workers,
                log_level="warning", access_log=False, **bounded)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class ThreadedServer:
    """uvicorn serving `app` on 127.0.0.1:`port` in a daemon thread (use as a context manager)."""

    def __init__(self, app, port: int | None = None, host: str = "127.0.0.1"):
        import uvicorn

        from pipeline.review.limits import Limits, protocol_for

        self.port = port or free_port()
        self.url = f"http://{host}:{self.port}"
        limits = getattr(getattr(app, "state", None), "limits", None) or Limits()
        self.server = uvicorn.Server(uvicorn.Config(app, host=host, port=self.port, log_level="warning",
                                                    access_log=False, limit_concurrency=512,
                                                    http=protocol_for(limits)))
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def __enter__(self) -> ThreadedServer:
        self.thread.start()
        deadline = time.monotonic() + 15
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("review server did not start")
            time.sleep(0.02)
        return self

    def __exit__(self, *exc) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)
