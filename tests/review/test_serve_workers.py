"""`recover review serve --workers 2`: two server processes on one database (SQLite file or
PostgreSQL), reviewers racing."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import yaml
from sqlalchemy import func, select

from pipeline.review.db import Item, Review, User, read_session
from pipeline.review.server import free_port

REPO = Path(__file__).resolve().parents[2]


def test_two_server_processes_lose_no_decision_and_never_exceed_k(tmp_path, run_dir, db_url, engine, people, items):
    cfg = tmp_path / "c.yaml"
    stage3 = {"reviews_per_item": 2, **({} if db_url.startswith("sqlite") else {"db_url": db_url})}
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(run_dir)}, "stage3": stage3}))
    port = free_port()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    server = subprocess.Popen([sys.executable, "-c", "from pipeline.cli import app; app()", "review", "serve",
                               "-c", str(cfg), "--port", str(port), "--workers", "2"], cwd=REPO, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(url + "/", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline and server.poll() is None, server.stderr.read().decode()[-2000:]
            time.sleep(0.2)
        names = ["ann", "bob", "cat", "dan"]
        acked: list[tuple[int, str]] = []
        lock, barrier = threading.Lock(), threading.Barrier(len(names))

        def reviewer(name: str) -> None:
            # a fresh connection per request: requests land on either process
            headers = {"Authorization": f"Bearer {people[name]}", "Connection": "close"}
            barrier.wait()
            while (nxt := httpx.post(url + "/api/queue/next", headers=headers, timeout=30).json()["item"]) is not None:
                body = {"decision": "flag", "reason": "racing", "version": 0, "idempotency_key": f"{name}-{nxt}"}
                r = httpx.post(f"{url}/api/items/{nxt}/review", json=body, headers=headers, timeout=30)
                if r.status_code == 200:
                    with lock:
                        acked.append((nxt, name))

        threads = [threading.Thread(target=reviewer, args=(n,)) for n in names]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=120)
        assert not any(t.is_alive() for t in threads)
    finally:
        server.terminate()
        server.wait(timeout=20)
    with read_session(engine) as s:
        stored = set(s.execute(select(Review.item_id, User.name).join(User, User.id == Review.reviewer_id)).all())
        per_item = dict(s.execute(select(Review.item_id, func.count()).group_by(Review.item_id)).all())
        over = s.scalar(select(func.count(Item.id)).where(Item.n_reviews > Item.required_reviews))
    assert set(acked) == stored and over == 0
    assert per_item == {i: 2 for i in items}
