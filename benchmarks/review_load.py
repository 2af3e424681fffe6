"""Load on the review server at a human pace, on SQLite and PostgreSQL.

Simulated reviewers each loop: POST /api/queue/next -> the item page (GET item, frames,
evidence) -> watch for a think time -> POST the decision. Think times are drawn from a seeded
gamma distribution (shape 4, default mean 8 s: someone watching a 10-30 s clip, stepping the
playhead): 200 such reviewers make about 25 decisions/s, 25 times a real team of 20.
Configurations (each its own database and `recover review serve` processes):
  sqlite-1  SQLite, 1 server process     sqlite-2  SQLite, 2     postgres-2  PostgreSQL, 2
(PostgreSQL: a throwaway cluster, `tests/pg_cluster.py`). With `--base DIR` the same SQLite
configurations run again with the server code of another checkout (e.g. the issue's base
commit, `git worktree add --detach DIR b67844a`), in the same run, for comparison; every
database is built by its own checkout's code (`prepare`), all items up front.
Reported per configuration: decision and item-page p50/p95/p99, decisions/s, server CPU per
item (the server processes; on PostgreSQL also the database's), decisions lost (acknowledged
but not stored), items over K, refusals (decisions not answered 200). A saturation run
(`--saturation-s`, 20 reviewers, think 0) gives the most decisions/s: reported, never an aim.
Aims, human pace, this checkout only: decision p95 <= 100 ms, item page p95 <= 150 ms,
0 lost, 0 over K, 0 refused; the exit status is 1 when one is missed (`missed`).

    .venv/bin/python benchmarks/review_load.py [--reviewers 200] [--duration-s 300]
        [--think-mean-s 8] [--saturation-s 30] [--configs sqlite-1,sqlite-2,postgres-2] [--base DIR]
Results: printed, and written to benchmarks/results/review_load.json.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import yaml
from sqlalchemy import create_engine, func, select

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.review.db import Item, Review, User, read_session  # noqa: E402
from pipeline.review.server import free_port  # noqa: E402
from tests.review.sample_run import build  # noqa: E402

CONFIGS = {"sqlite-1": ("sqlite", 1), "sqlite-2": ("sqlite", 2), "postgres-2": ("postgresql", 2)}
AIMS = {"decision_p95_ms": 100.0, "item_page_p95_ms": 150.0}
SATURATION_REVIEWERS = 20


def prepare(code: Path, db_url: str, run: Path, n_items: int, n_users: int, k: int = 2,
            build_run: bool = False) -> list[str]:
    """The database as checkout `code` builds it (its schema, migrations and enqueue, through
    `review_cpu.py _setup`): `n_items` queue items sharing the sample run's media, and the
    tokens of `n_users` reviewers (`build_run`: `code` first writes the sample run). Another checkout's server thus runs on a database of its own
    making (the base commit's schema lacks later columns, e.g. `leases.taken_at`)."""
    env = {**os.environ, "PYTHONPATH": str(code)}
    out = subprocess.run([sys.executable, str(REPO / "benchmarks" / "review_cpu.py"), "_setup", "--code", str(code),
                          "--db", db_url, "--run", str(run), "--items", str(n_items), "--users", str(n_users),
                          "--k", str(k)] + (["--build-run"] if build_run else []),
                         cwd=code, env=env, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) used so far by process `pid` and its live children (the
    server's worker processes, PostgreSQL's backends): other work on the machine barely changes it."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0.0
    pids = [pid]
    try:
        pids += [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        pass
    for q in pids:
        try:
            fields = Path(f"/proc/{q}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / tick
    return total


def pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    values = sorted(values)
    return round(values[min(len(values) - 1, int(round(q / 100 * (len(values) - 1))))] * 1000, 1)


class _Retrying:
    """A client that sends a request again once when its connection fails before an answer,
    as a browser does: after a think time longer than the server's keep-alive timeout (5 s),
    a pooled connection may be closed just as it is reused. Every request here is safe to
    repeat (a decision carries its idempotency key)."""

    def __init__(self, client: httpx.Client):
        self.client = client

    def _send(self, method: str, path: str, **kw) -> httpx.Response:
        try:
            return self.client.request(method, path, **kw)
        except httpx.TransportError:
            return self.client.request(method, path, **kw)

    def get(self, path: str, **kw) -> httpx.Response:
        return self._send("GET", path, **kw)

    def post(self, path: str, **kw) -> httpx.Response:
        return self._send("POST", path, **kw)


def _reviewers(url: str, tokens: list[tuple[int, str]], think_mean_s: float, seed: int, stop_at: float,
               barrier, out) -> None:
    """One client process: a thread per reviewer, each looping until `stop_at` (wall clock)
    or until the queue is empty. A decision still being thought about at `stop_at` is not sent."""
    page_s: list[float] = []
    post_s: list[float] = []
    acked: list[tuple[int, str, dict]] = []
    errors: list[str] = []
    lock = threading.Lock()
    stop = threading.Event()

    def reviewer(token: str, idx: int) -> None:
        rng = random.Random(seed * 100_003 + idx)
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=60) as client:
            c = _Retrying(client)
            barrier.wait()
            # people do not all start at once: a first item somewhere in the first think time
            if think_mean_s and stop.wait(rng.uniform(0, think_mean_s)):
                return
            while time.time() < stop_at:
                n = c.post("/api/queue/next")
                if n.status_code != 200:
                    with lock:
                        errors.append(f"queue/next {n.status_code} {n.text[:120]}")
                    continue
                nxt = n.json()["item"]
                if nxt is None:
                    return
                t0 = time.perf_counter()
                r = c.get(f"/api/items/{nxt}")
                bad = [x for x in (r, c.get(f"/api/items/{nxt}/frames"), c.get(f"/api/items/{nxt}/evidence"))
                       if x.status_code != 200]
                t1 = time.perf_counter()
                if bad:
                    with lock:
                        errors.extend(f"{x.url.path} {x.status_code} {x.text[:120]}" for x in bad)
                    continue
                if think_mean_s:  # a person watching the clip before deciding
                    think = rng.gammavariate(4.0, think_mean_s / 4.0)
                    if stop.wait(min(think, max(0.0, stop_at - time.time()))) or time.time() >= stop_at:
                        return
                body = {"decision": "revise", "version": r.json()["version"], "idempotency_key": f"{idx}-{nxt}",
                        "fields": {"recovery_level": f"L{1 + (idx + nxt) % 4}"}}
                t2 = time.perf_counter()
                d = c.post(f"/api/items/{nxt}/review", json=body)
                t3 = time.perf_counter()
                with lock:
                    page_s.append(t1 - t0)
                    post_s.append(t3 - t2)
                    if d.status_code == 200:
                        acked.append((nxt, f"r{idx}", d.json()["values"]))
                    else:
                        errors.append(f"{d.status_code} {d.text[:120]}")

    threads = [threading.Thread(target=reviewer, args=(tok, i), daemon=True) for i, tok in tokens]
    for th in threads:
        th.start()
    while any(th.is_alive() for th in threads):
        if time.time() >= stop_at:
            stop.set()
        time.sleep(0.2)
    out.put({"page_s": page_s, "post_s": post_s, "acked": acked, "errors": errors})


def load(url: str, tokens: list[str], think_mean_s: float, duration_s: float, seed: int, clients: int) -> dict:
    """N reviewers spread over `clients` processes (so that one interpreter lock does not add
    its own waits to every latency)."""
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    clients = max(1, min(clients, len(tokens)))
    barrier, out = ctx.Barrier(len(tokens)), ctx.Queue()
    groups = [[(i, tok) for i, tok in enumerate(tokens) if i % clients == g] for g in range(clients)]
    t = time.perf_counter()
    stop_at = time.time() + duration_s + 5  # + the barrier and start of the client processes
    procs = [ctx.Process(target=_reviewers, args=(url, grp, think_mean_s, seed, stop_at, barrier, out))
             for grp in groups]
    for pr in procs:
        pr.start()
    parts = [out.get(timeout=duration_s + 600) for _ in procs]
    for pr in procs:
        pr.join()
    wall = time.perf_counter() - t
    page_s, post_s = (sum((x[k] for x in parts), []) for k in ("page_s", "post_s"))
    acked, errors = sum((x["acked"] for x in parts), []), sum((x["errors"] for x in parts), [])
    return {"reviewers": len(tokens), "think_mean_s": think_mean_s, "decisions": len(acked), "refused": len(errors),
            "errors": errors[:5], "wall_s": round(wall, 1), "decisions_per_s": round(len(acked) / wall, 1),
            **{f"item_page_p{q}_ms": pct(page_s, q) for q in (50, 95, 99)},
            **{f"decision_p{q}_ms": pct(post_s, q) for q in (50, 95, 99)},
            "_acked": acked}


def check(engine, acked: list[tuple[int, str, dict]]) -> dict:
    """Decisions acknowledged but not stored as acknowledged, and items with more than K reviews."""
    with read_session(engine) as s:
        rows = s.execute(select(Review.item_id, User.name, Review.values).join(User, User.id == Review.reviewer_id)).all()
        per_item = select(Review.item_id, func.count().label("n")).group_by(Review.item_id).subquery()
        over = s.scalar(select(func.count()).select_from(per_item.join(Item, Item.id == per_item.c.item_id))
                        .where(per_item.c.n > Item.required_reviews))
    stored = {(i, n): v for i, n, v in rows}
    return {"lost_decisions": sum(1 for i, n, v in acked if stored.get((i, n)) != v), "items_over_k": over}


def missed(name: str, res: dict, aims: dict = AIMS) -> list[str]:
    """The aims a human-pace run missed: latencies within the aims (NaN, no decisions at all,
    misses too), nothing lost, nothing over K, nothing refused."""
    out = []
    for key, aim in aims.items():
        if not res[key] <= aim:
            out.append(f"{name}: {key.replace('_ms', '')} {res[key]} ms > {aim:g} ms")
    if res["lost_decisions"]:
        out.append(f"{name}: {res['lost_decisions']} decision(s) lost")
    if res["items_over_k"]:
        out.append(f"{name}: {res['items_over_k']} item(s) over K")
    if res["refused"]:
        out.append(f"{name}: {res['refused']} decision(s) refused: {res['errors'][:1]}")
    return out


def wait_serving(url: str, proc: subprocess.Popen, failure: Callable[[], str]) -> None:
    """Return once the server at `url` answers its page; raise with `failure()` if its process
    exits or 300 s pass (imports alone take a minute on a busy 2-core machine)."""
    deadline = time.monotonic() + 300
    while True:
        try:
            if httpx.get(url + "/", timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(failure())
        time.sleep(0.2)


class Server:
    """`recover review serve` of checkout `code` on a config, as its own processes."""

    def __init__(self, code: Path, cfg: Path, workers: int):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        env = {**os.environ, "PYTHONUNBUFFERED": "1",
               "PYTHONPATH": os.pathsep.join([str(code), os.environ.get("PYTHONPATH", "")])}
        self.log = cfg.with_suffix(".log")  # a file, not a pipe: a full pipe would stall the server
        self.proc = subprocess.Popen([sys.executable, "-c", "from pipeline.cli import app; app()", "review", "serve",
                                      "--config", str(cfg), "--port", str(self.port), "--workers", str(workers)],
                                     cwd=code, stdout=subprocess.DEVNULL, stderr=open(self.log, "wb"), env=env)
        wait_serving(self.url, self.proc, lambda: f"server did not start: {self.log.read_text()[-2000:]}")

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def run_config(name: str, code: Path, db_url: str, workers: int, run: Path, tmp: Path, args,
               pg_pid: int | None) -> dict:
    # enough items for everyone at the expected pace, with room to spare, then for the saturation run
    expected = args.reviewers * args.duration_s / max(args.think_mean_s, 0.5)
    n_items = int(1.5 * expected / args.k) + 50
    if args.saturation_s > 0:
        n_items += int(300 * args.saturation_s / args.k) + 50
    tokens = prepare(code, db_url, run, n_items, args.reviewers, args.k)
    engine = create_engine(db_url)  # reads only: another checkout's database is not migrated by this code
    cfg = tmp / f"{name}.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(run)},
                                   "stage3": {"reviews_per_item": args.k, "db_url": db_url}}))
    server = Server(code, cfg, workers)
    out: dict = {"config": name, "code": str(code), "workers": workers}
    try:
        for mode, n, think, duration in (("human", args.reviewers, args.think_mean_s, args.duration_s),
                                         ("saturation", SATURATION_REVIEWERS, 0.0, args.saturation_s)):
            if duration <= 0:
                continue
            cpu0, db0 = cpu_s(server.proc.pid), cpu_s(pg_pid) if pg_pid else 0.0
            res = load(server.url, tokens[:n], think, duration, args.seed, args.clients)
            n_dec = max(1, res["decisions"])
            res["server_cpu_ms_per_item"] = round((cpu_s(server.proc.pid) - cpu0) * 1000 / n_dec, 2)
            if pg_pid:
                res["db_cpu_ms_per_item"] = round((cpu_s(pg_pid) - db0) * 1000 / n_dec, 2)
            res.update(check(engine, res.pop("_acked")))
            out[mode] = res
            if res["refused"]:
                tail = [ln for ln in server.log.read_text(errors="replace").splitlines() if "Error" in ln][-3:]
                print(f"  {name} {mode}: refusals {res['errors'][:3]}; server log: {tail}", flush=True)
            print(f"  {name} {mode}: {json.dumps({k: v for k, v in res.items() if k != 'errors'})}", flush=True)
    finally:
        server.stop()
        engine.dispose()
    return out


COLS = ["reviewers", "decisions", "decisions_per_s", "item_page_p50_ms", "item_page_p95_ms", "item_page_p99_ms",
        "decision_p50_ms", "decision_p95_ms", "decision_p99_ms", "server_cpu_ms_per_item", "db_cpu_ms_per_item",
        "lost_decisions", "items_over_k", "refused"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reviewers", type=int, default=200)
    ap.add_argument("--duration-s", type=float, default=300.0, help="length of each human-pace run")
    ap.add_argument("--think-mean-s", type=float, default=8.0, help="mean think time per item (seeded gamma, shape 4)")
    ap.add_argument("--saturation-s", type=float, default=30.0, help="length of each saturation run (0: none)")
    ap.add_argument("--k", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--clients", type=int, default=4, help="client processes the reviewers are spread over")
    ap.add_argument("--configs", default=",".join(CONFIGS))
    ap.add_argument("--base", type=Path, help="another checkout whose server also runs the SQLite configurations")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="review_load_"))
    run = tmp / "run"
    build(run, n_episodes=4, n_quarantined=0, steps=200)
    names = [c for c in args.configs.split(",") if c]
    plan = [(n, REPO) for n in names]
    if args.base:
        plan += [(n, args.base.resolve()) for n in names if CONFIGS[n][0] == "sqlite"]
    pg = None
    results = []
    try:
        for name, code in plan:
            backend, workers = CONFIGS[name]
            label = name if code == REPO else f"{name}@base"
            print(f"{label}: {args.reviewers} reviewers, think mean {args.think_mean_s} s, {args.duration_s:g} s; "
                  f"saturation {args.saturation_s:g} s", flush=True)
            if backend == "sqlite":
                db_url = f"sqlite:///{tmp / (label.replace('@', '_') + '.sqlite')}"
            else:
                if pg is None:
                    from tests.pg_cluster import PgCluster

                    pg = PgCluster(max_connections=400).__enter__()
                db_url = pg.new_database()
            results.append({**run_config(label, code, db_url, workers, run, tmp, args,
                                         pg.proc.pid if backend == "postgresql" else None), "label": label})
    finally:
        if pg is not None:
            pg.__exit__(None, None, None)
    misses = []
    for mode in ("human", "saturation"):
        print(f"\n{mode}" + (f" (mean think {args.think_mean_s} s)" if mode == "human" else " (think 0: reported, never an aim)"))
        rows = [r for r in results if mode in r]
        print(f"{'metric':<24}" + "".join(f"{r['label']:>18}" for r in rows))
        for c in COLS:
            print(f"{c:<24}" + "".join(f"{str(r[mode].get(c, '')):>18}" for r in rows))
        if mode == "human":
            misses += [m for r in rows if r["code"] == str(REPO) for m in missed(r["label"], r["human"])]
    load_avg = [round(x, 2) for x in os.getloadavg()]
    print(f"machine: {os.cpu_count()} cores, load average {load_avg} (other work on the machine slows every request)")
    print("aims (human pace, this checkout): " + ("all met" if not misses else "MISSED: " + "; ".join(misses)))
    out = REPO / "benchmarks" / "results" / "review_load.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "results": results,
                               "missed": misses, "cpu_count": os.cpu_count(), "load_avg": load_avg}, indent=2))
    return 1 if misses else 0


if __name__ == "__main__":
    sys.exit(main())
