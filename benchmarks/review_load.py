"""Load on the review server: p95 latency of the item page and of the decision POST with
20 concurrent reviewers on loopback (aim: decision p95 <= 100 ms), lost decisions and items
over K (both must be 0). Exits 1 when any aim is missed (`missed`).

Runs the real server (`recover review serve --workers 2`, its own processes, SQLite in WAL mode) on a
synthetic run folder (`tests/review/sample_run.py`), then reviewer threads that each loop
  POST /api/queue/next -> item page (GET item, frames, evidence) -> POST decision
until the queue is empty. One reviewer first, then N at once, printed side by side. The
reviewers are threads spread over 4 client processes (20 people use 20 browsers). The
server's CPU time per item (5 requests) is printed too: unlike latencies, other work on
the machine barely changes it.
A decision is lost when the server acknowledged it (200) but the database lacks it.

    .venv/bin/python benchmarks/review_load.py [--reviewers 20] [--items 300] [--k 2] [--think-s 0]
        [--workers 2] [--clients 4] [--aim-ms 100]
Results: printed, and written to benchmarks/results/review_load.json.
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

import httpx
import yaml
from sqlalchemy import func, select

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.review.auth import add_user  # noqa: E402
from pipeline.review.db import Item, Review, User, make_engine, read_session, write_session  # noqa: E402
from pipeline.review.enqueue import enqueue  # noqa: E402
from pipeline.review.server import free_port  # noqa: E402
from pipeline.stage3.inputs import collect, context  # noqa: E402
from pipeline.stage3.run import proposal_for  # noqa: E402
from pipeline.records import Category, Characterization, Level  # noqa: E402
from tests.review.sample_run import build  # noqa: E402


def fill(run: Path, engine, n_items: int, k: int, tag: str) -> None:
    """n_items queue items sharing the sample run's media (distinct episode keys)."""
    units = [u for u in collect(run) if u.localization is not None]
    with write_session(engine) as s:
        for i in range(n_items):
            u = units[i % len(units)]
            ch = Characterization(key=u.key, recovery_level=Level.L3, failure_category=Category.object_displacement,
                                  recovery_action="Set the bowl upright", source="simstate")
            enqueue(s, key=f"{u.key}-{tag}{i:05d}", instruction=u.localization.instruction, proposal=proposal_for(u, ch, None),
                    context=context(run, u, 20, 10.0), required_reviews=k)


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) used so far by process `pid` and its live children (the
    server's worker processes): a figure that other work on the machine barely changes."""
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


def p(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    values = sorted(values)
    return values[min(len(values) - 1, int(round(q / 100 * (len(values) - 1))))] * 1000


def _reviewers(url: str, tokens: list[tuple[int, str]], think_s: float, barrier, out) -> None:
    """One client process: a thread per reviewer, each looping until the queue is empty."""
    page_s: list[float] = []
    item_s: list[float] = []
    post_s: list[float] = []
    acked: list[tuple[int, str, dict]] = []
    errors: list[str] = []
    lock = threading.Lock()

    def reviewer(token: str, idx: int) -> None:
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=30) as c:
            barrier.wait()
            while True:
                nxt = c.post("/api/queue/next").json()["item"]
                if nxt is None:
                    return
                t0 = time.perf_counter()
                r = c.get(f"/api/items/{nxt}")
                t1 = time.perf_counter()
                c.get(f"/api/items/{nxt}/frames")
                c.get(f"/api/items/{nxt}/evidence")
                t2 = time.perf_counter()
                if think_s:  # a person watching the video before deciding
                    time.sleep(think_s)
                body = {"decision": "revise", "version": r.json()["version"], "idempotency_key": f"{idx}-{nxt}",
                        "fields": {"recovery_level": f"L{1 + (idx + nxt) % 4}"}}
                t3 = time.perf_counter()
                d = c.post(f"/api/items/{nxt}/review", json=body)
                t4 = time.perf_counter()
                with lock:
                    item_s.append(t1 - t0)
                    page_s.append(t2 - t0)
                    post_s.append(t4 - t3)
                    if d.status_code == 200:
                        acked.append((nxt, f"r{idx}", d.json()["values"]))
                    else:
                        errors.append(f"{d.status_code} {d.text[:120]}")

    threads = [threading.Thread(target=reviewer, args=(tok, i)) for i, tok in tokens]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    out.put({"page_s": page_s, "item_s": item_s, "post_s": post_s, "acked": acked, "errors": errors})


def load(url: str, tokens: list[str], think_s: float = 0.0, clients: int = 4) -> dict:
    """N reviewers spread over `clients` processes (20 people are 20 browsers, not 20 threads
    sharing one interpreter lock: that lock would add its own waits to every latency)."""
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    clients = max(1, min(clients, len(tokens)))
    barrier, out = ctx.Barrier(len(tokens)), ctx.Queue()
    groups = [[(i, tok) for i, tok in enumerate(tokens) if i % clients == g] for g in range(clients)]
    t = time.perf_counter()
    procs = [ctx.Process(target=_reviewers, args=(url, grp, think_s, barrier, out)) for grp in groups]
    for pr in procs:
        pr.start()
    parts = [out.get(timeout=900) for _ in procs]
    for pr in procs:
        pr.join()
    wall = time.perf_counter() - t
    page_s, item_s, post_s = (sum((x[k] for x in parts), []) for k in ("page_s", "item_s", "post_s"))
    acked, errors = sum((x["acked"] for x in parts), []), sum((x["errors"] for x in parts), [])
    return {"reviewers": len(tokens), "decisions": len(acked), "refused": len(errors), "errors": errors[:5],
            "wall_s": round(wall, 2), "decisions_per_s": round(len(acked) / wall, 1),
            "item_json_p50_ms": round(p(item_s, 50), 1), "item_json_p95_ms": round(p(item_s, 95), 1),
            "item_page_p50_ms": round(p(page_s, 50), 1), "item_page_p95_ms": round(p(page_s, 95), 1),
            "decision_p50_ms": round(p(post_s, 50), 1), "decision_p95_ms": round(p(post_s, 95), 1),
            "_acked": acked}


def check(engine, acked: list[tuple[int, str, dict]], k: int) -> dict:
    with read_session(engine) as s:
        rows = s.execute(select(Review.item_id, User.name, Review.values).join(User, User.id == Review.reviewer_id)).all()
        over = s.scalar(select(func.count(Item.id)).where(Item.n_reviews > k))
    stored = {(i, n): v for i, n, v in rows}
    lost = sum(1 for i, n, v in acked if stored.get((i, n)) != v)
    return {"lost_decisions": lost, "stored": len(stored), "items_over_k": over}


def missed(one: dict, many: dict, aim_ms: float) -> list[str]:
    """The aims this run missed (the exit status is 1 when there is any): decision p95 of the
    N-reviewer run within the aim, no decision lost, no item over K, none refused."""
    out = []
    if not many["decision_p95_ms"] <= aim_ms:  # NaN (no decisions at all) misses too
        out.append(f"decision p95 {many['decision_p95_ms']} ms > {aim_ms:g} ms")
    for name, res in (("1 reviewer", one), (f"{many['reviewers']} reviewers", many)):
        if res["lost_decisions"]:
            out.append(f"{res['lost_decisions']} decision(s) lost ({name})")
        if res["items_over_k"]:
            out.append(f"{res['items_over_k']} item(s) over K ({name})")
        if res["refused"]:
            out.append(f"{res['refused']} decision(s) refused ({name}): {res['errors'][:1]}")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reviewers", type=int, default=20)
    ap.add_argument("--items", type=int, default=300, help="items for the N-reviewer run")
    ap.add_argument("--k", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2, help="server processes (`recover review serve --workers`)")
    ap.add_argument("--aim-ms", type=float, default=100.0, help="decision p95 aim of the N-reviewer run")
    ap.add_argument("--clients", type=int, default=4, help="client processes the reviewers are spread over")
    ap.add_argument("--think-s", type=float, default=0.0,
                    help="pause between loading an item and deciding (0 = a stress test: nobody watches)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="review_load_"))
    run = tmp / "run"
    build(run, n_episodes=4, n_quarantined=0, steps=200)
    cfg = tmp / "load.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(run)}, "stage3": {"reviews_per_item": args.k}}))
    engine = make_engine(f"sqlite:///{run / 'stage3' / 'review.sqlite'}")
    tokens = [add_user(engine, f"r{i}", "reviewer") for i in range(args.reviewers)]
    port = free_port()
    # this interpreter and this checkout (the same code as `recover review serve`)
    server = subprocess.Popen([sys.executable, "-c", "from pipeline.cli import app; app()", "review", "serve",
                               "--config", str(cfg), "--port", str(port), "--workers", str(args.workers)],
                              cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              env={**os.environ, "PYTHONUNBUFFERED": "1",
                                   "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])})
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(200):
            try:
                httpx.get(url + "/", timeout=1)
                break
            except httpx.HTTPError:
                time.sleep(0.1)
        results = []
        for n, items in ((1, max(20, args.items // 10)), (args.reviewers, args.items)):
            # a one-reviewer queue holds items with K = 1 so that single person can empty it
            fill(run, engine, items, args.k if n > 1 else 1, tag=f"n{n}-")
            cpu0 = cpu_s(server.pid)
            res = load(url, tokens[:n], args.think_s, args.clients)
            res["server_cpu_ms_per_item"] = round((cpu_s(server.pid) - cpu0) * 1000 / max(1, res["decisions"]), 1)
            res.update(check(engine, res.pop("_acked"), args.k))
            results.append(res)
    finally:
        server.terminate()
        server.wait(timeout=10)
    one, many = results
    cols = ["reviewers", "decisions", "decisions_per_s", "item_json_p95_ms", "item_page_p50_ms", "item_page_p95_ms",
            "decision_p50_ms", "decision_p95_ms", "server_cpu_ms_per_item", "refused", "lost_decisions",
            "items_over_k"]
    print(f"{'metric':<20}{'1 reviewer':>14}{f'{args.reviewers} reviewers':>16}{'ratio':>9}")
    for c in cols:
        a, b = one[c], many[c]
        ratio = f"{b / a:.2f}x" if isinstance(a, (int, float)) and a else ""
        print(f"{c:<20}{a:>14}{b:>16}{ratio:>9}")
    misses = missed(one, many, args.aim_ms)
    verdict = "OK" if not misses else "MISSED: " + "; ".join(misses)
    print(f"think time {args.think_s} s per item; p95 with {args.reviewers} reviewers: item page "
          f"{many['item_page_p95_ms']} ms, decision {many['decision_p95_ms']} ms (aim <= {args.aim_ms:g} ms); "
          f"lost decisions: {many['lost_decisions'] + one['lost_decisions']} -> {verdict}")
    out = REPO / "benchmarks" / "results" / f"review_load{f'_think{args.think_s:g}s' if args.think_s else ''}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    load_avg = [round(x, 2) for x in os.getloadavg()]
    print(f"machine: {os.cpu_count()} cores, load average {load_avg} (other work on the machine slows every request)")
    out.write_text(json.dumps({"one": one, "many": many, "cpu_count": os.cpu_count(), "load_avg": load_avg}, indent=2))
    return 1 if misses else 0


if __name__ == "__main__":
    sys.exit(main())
