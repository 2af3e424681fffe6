"""Building and running the review server from a run config.

Inputs: the validated `Config` (run folder, `stage3` section).
Outputs: the engine, the app; `serve` blocks running uvicorn; `ThreadedServer` runs it in
a background thread on loopback (tests, the load benchmark) and stops it cleanly.
"""

from __future__ import annotations

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
                         lease_seconds=s.lease_seconds, control_hz=cfg.stage1.rollout.control_hz)


def engine_for(cfg: Config) -> Engine:
    return make_engine(db_url(cfg))


def build_app(cfg: Config, engine: Engine | None = None, docs: bool = False):
    from pipeline.review.api import create_app

    return create_app(Path(cfg.out), engine or engine_for(cfg), settings(cfg), docs=docs)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class ThreadedServer:
    """uvicorn serving `app` on 127.0.0.1:`port` in a daemon thread (use as a context manager)."""

    def __init__(self, app, port: int | None = None, host: str = "127.0.0.1"):
        import uvicorn

        self.port = port or free_port()
        self.url = f"http://{host}:{self.port}"
        self.server = uvicorn.Server(uvicorn.Config(app, host=host, port=self.port, log_level="warning",
                                                    access_log=False, limit_concurrency=512))
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
