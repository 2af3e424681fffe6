"""The review server's CPU time per reviewer cycle, and where it goes.

A cycle is what one reviewer's browser asks of the server per item: POST /api/queue/next,
the item page (GET /api/items/{id}, its /frames and /evidence), POST the decision (K = 2, so
every second decision closes an item). A few clients run cycles back to back against
`recover review serve` (its own process, one worker); the figure is that process's CPU time
(user + system, /proc) over the measured cycles divided by their number: unlike latency, it
barely changes with other work on the machine. With `--base DIR` the same cycles run, in the
same invocation, against the server of another checkout (e.g. this issue's base commit:
`git worktree add --detach DIR b67844a`), whose own code builds its database.
`--profile FILE` instead runs this checkout's server in-process under cProfile (one profiler
per thread: the event loop and the threadpool, each timed by its thread's CPU clock) and
writes the merged stats to FILE (read them with `python -m pstats FILE`).

    .venv/bin/python benchmarks/review_cpu.py [--cycles 300] [--warmup 40] [--clients 4] [--queue 2000]
        [--backend sqlite|postgresql] [--base DIR] [--repeat N] [--profile FILE]
Results: printed, and written to benchmarks/results/review_cpu.json.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _setup(code: Path, db_url: str, run: Path, n_items: int, n_users: int, build_run: bool, k: int = 2) -> None:
    """Runs under `code`'s own pipeline (its schema, its enqueue): prints the users' tokens."""
    sys.path.insert(0, str(code))
    from pipeline.records import Category, Characterization, Level
    from pipeline.review.auth import add_user
    from pipeline.review.db import make_engine, write_session
    from pipeline.review.enqueue import enqueue
    from pipeline.stage3.inputs import collect, context
    from pipeline.stage3.run import proposal_for
    from tests.review.sample_run import build

    if build_run:
        build(run, n_episodes=4, n_quarantined=0, steps=200)
    engine = make_engine(db_url)
    units = [u for u in collect(run) if u.localization is not None]
    with write_session(engine) as s:
        for i in range(n_items):
            u = units[i % len(units)]
            ch = Characterization(key=u.key, recovery_level=Level.L3, failure_category=Category.object_displacement,
                                  recovery_action="Set the bowl upright", source="simstate")
            enqueue(s, key=f"{u.key}-c{i:05d}", instruction=u.localization.instruction,
                    proposal=proposal_for(u, ch, None), context=context(run, u, 20, 10.0), required_reviews=k)
    tokens = [add_user(engine, f"r{i}", "reviewer") for i in range(n_users)]
    engine.dispose()
    print(json.dumps(tokens))


def _serve_profiled(code: Path, cfg: Path, port: int, out: Path) -> None:
    """This checkout's server in this process, every thread profiled by its own CPU clock.
    SIGUSR1 starts the profilers (after the warm-up); SIGUSR2 stops the server and the merged
    stats go to `out`."""
    import cProfile
    import pstats
    import signal

    sys.path.insert(0, str(code))
    import anyio.to_thread
    import uvicorn

    from pipeline.config import load_config
    from pipeline.review.limits import BoundedHttpProtocol
    from pipeline.review.server import build_app

    profiles: list[cProfile.Profile] = []
    local = threading.local()
    on = threading.Event()
    orig = anyio.to_thread.run_sync

    def thread_profile() -> cProfile.Profile:
        p = getattr(local, "p", None)
        if p is None:
            p = local.p = cProfile.Profile(time.thread_time)
            profiles.append(p)
        return p

    async def run_sync(func, *args, **kw):
        def profiled(*a):
            if not on.is_set():
                return func(*a)
            p = thread_profile()
            p.enable()
            try:
                return func(*a)
            finally:
                p.disable()
        return await orig(profiled, *args, **kw)

    anyio.to_thread.run_sync = run_sync
    main = cProfile.Profile(time.thread_time)
    profiles.append(main)

    def start(*_):
        on.set()
        main.enable()

    signal.signal(signal.SIGUSR1, start)
    app = build_app(load_config(cfg))
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning",
                                           access_log=False, http=BoundedHttpProtocol))
    # SIGUSR2 stops it (uvicorn re-raises a SIGTERM it caught, which would end the process
    # before the stats are written)
    signal.signal(signal.SIGUSR2, lambda *_: setattr(server, "should_exit", True))
    server.run()
    main.disable()
    stats = None
    for p in profiles:
        p.create_stats()
        if p.stats:
            stats = pstats.Stats(p) if stats is None else stats.add(p)
    stats.dump_stats(str(out))


def _cycles(url: str, tokens: list[str], n: int) -> dict:
    """`n` reviewer cycles spread over one thread per token; returns counts of failures."""
    import httpx

    left = [n]
    lock = threading.Lock()
    bad: list[str] = []

    def reviewer(idx: int, token: str) -> None:
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=120) as c:
            while True:
                with lock:
                    if left[0] <= 0:
                        return
                    left[0] -= 1
                nxt = c.post("/api/queue/next").json()["item"]
                if nxt is None:
                    bad.append("queue empty")
                    return
                page = [c.get(f"/api/items/{nxt}"), c.get(f"/api/items/{nxt}/frames"),
                        c.get(f"/api/items/{nxt}/evidence")]
                if any(r.status_code != 200 for r in page):
                    bad.append(f"page {[r.status_code for r in page]}")
                    continue
                body = {"decision": "revise", "version": page[0].json()["version"], "idempotency_key": f"{idx}-{nxt}",
                        "fields": {"recovery_level": f"L{1 + (idx + nxt) % 4}"}}
                d = c.post(f"/api/items/{nxt}/review", json=body)
                if d.status_code != 200:
                    bad.append(f"review {d.status_code} {d.text[:100]}")

    threads = [threading.Thread(target=reviewer, args=(i, t)) for i, t in enumerate(tokens)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    return {"failed": len(bad), "errors": bad[:3]}


def measure(label: str, code: Path, run: Path, tmp: Path, args, db_url: str, build_run: bool) -> dict:
    import yaml

    sys.path.insert(0, str(REPO))
    from benchmarks.review_load import Server, cpu_s, prepare

    n_items = max(args.queue, (args.cycles + args.warmup) // 2 + 2 * args.clients + 10)
    tokens = prepare(code, db_url, run, n_items, args.clients, build_run=build_run)
    cfg = tmp / f"{label}.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(run)}, "stage3": {"reviews_per_item": 2, "db_url": db_url}}))
    if args.profile:
        server = _ProfiledServer(code, cfg, Path(args.profile).resolve())
    else:
        server = Server(code, cfg, 1)
    try:
        warm = _cycles(server.url, tokens, args.warmup)
        if args.profile:
            server.proc.send_signal(__import__("signal").SIGUSR1)
        cpu0, t0 = cpu_s(server.proc.pid), time.perf_counter()
        res = _cycles(server.url, tokens, args.cycles)
        cpu = cpu_s(server.proc.pid) - cpu0
        wall = time.perf_counter() - t0
    finally:
        server.stop()
    out = {"label": label, "code": str(code), "backend": args.backend, "cycles": args.cycles, "clients": args.clients,
           "server_cpu_ms_per_cycle": round(cpu * 1000 / args.cycles, 2), "wall_s": round(wall, 1),
           "failed": res["failed"] + warm["failed"], "errors": res["errors"] + warm["errors"]}
    print(json.dumps(out), flush=True)
    return out


class _ProfiledServer:
    def __init__(self, code: Path, cfg: Path, out: Path):
        sys.path.insert(0, str(REPO))
        from benchmarks.review_load import wait_serving
        from pipeline.review.server import free_port

        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "_serve", "--code", str(code),
                                      "--config", str(cfg), "--port", str(self.port), "--out", str(out)],
                                     cwd=code, env={**os.environ, "PYTHONPATH": str(code)})
        wait_serving(self.url, self.proc, lambda: "profiled server did not start")

    def stop(self) -> None:
        import signal

        self.proc.send_signal(signal.SIGUSR2)
        self.proc.wait(timeout=120)


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "_setup":
        ap = argparse.ArgumentParser()
        ap.add_argument("_cmd")
        for a in ("--code", "--db", "--run"):
            ap.add_argument(a, required=True)
        ap.add_argument("--items", type=int, required=True)
        ap.add_argument("--users", type=int, required=True)
        ap.add_argument("--build-run", action="store_true")
        ap.add_argument("--k", type=int, default=2)
        a = ap.parse_args()
        _setup(Path(a.code), a.db, Path(a.run), a.items, a.users, a.build_run, a.k)
        return 0
    if len(sys.argv) > 1 and sys.argv[1] == "_serve":
        ap = argparse.ArgumentParser()
        ap.add_argument("_cmd")
        for a in ("--code", "--config", "--port", "--out"):
            ap.add_argument(a, required=True)
        a = ap.parse_args()
        _serve_profiled(Path(a.code), Path(a.config), int(a.port), Path(a.out))
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=300, help="measured cycles per server")
    ap.add_argument("--warmup", type=int, default=40, help="cycles before the measurement (imports, caches)")
    ap.add_argument("--clients", type=int, default=4, help="reviewers running cycles at once")
    ap.add_argument("--queue", type=int, default=2000,
                    help="items in the queue (a long queue, as in review_load.py's human-pace run)")
    ap.add_argument("--backend", choices=("sqlite", "postgresql"), default="sqlite")
    ap.add_argument("--base", type=Path, action="append", default=[],
                    help="another checkout whose server runs the same cycles (repeatable)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="rounds over the checkouts, interleaved (the machine's load drifts); the median is reported")
    ap.add_argument("--profile", help="profile this checkout's server into this pstats file (no --base)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="review_cpu_"))
    run = tmp / "run"
    plan = [("this", REPO)] + ([] if args.profile else [(f"base{i}", b.resolve()) for i, b in enumerate(args.base)])
    plan = [(f"{label}-{r}", label, code) for r in range(1 if args.profile else args.repeat) for label, code in plan]
    pg = None
    results = []
    try:
        for i, (run_label, label, code) in enumerate(plan):
            if args.backend == "sqlite":
                db_url = f"sqlite:///{tmp / run_label}.sqlite"
            else:
                if pg is None:
                    sys.path.insert(0, str(REPO))
                    from tests.pg_cluster import PgCluster

                    pg = PgCluster().__enter__()
                db_url = pg.new_database()
            results.append({**measure(run_label, code, run, tmp, args, db_url, build_run=i == 0), "label": label})
    finally:
        if pg is not None:
            pg.__exit__(None, None, None)
    print(f"\nserver CPU per reviewer cycle ({args.backend}, {args.clients} clients, {args.cycles} cycles, "
          f"{args.repeat} round(s); next + item + frames + evidence + decision):")
    summary = {}
    for label in dict.fromkeys(r["label"] for r in results):
        rs = [r for r in results if r["label"] == label]
        ms = sorted(r["server_cpu_ms_per_cycle"] for r in rs)
        summary[label] = {"code": rs[0]["code"], "median_ms": ms[len(ms) // 2], "runs_ms": [r["server_cpu_ms_per_cycle"] for r in rs]}
        print(f"  {label:<8} {ms[len(ms) // 2]:>8} ms (runs {summary[label]['runs_ms']})   "
              f"failed {sum(r['failed'] for r in rs)}   {rs[0]['code']}")
    out = REPO / "benchmarks" / "results" / "review_cpu.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "summary": summary, "results": results,
                               "load_avg": [round(x, 2) for x in os.getloadavg()]}, indent=2))
    return 1 if any(r["failed"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
