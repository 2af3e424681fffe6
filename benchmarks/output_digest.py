"""Digest every output of a run, to show that a change of code left the outputs byte-identical.

Runs stages 1-3 on a config, has two reviewers accept every proposal through the real review
server (HTTP, personal tokens, as people would), exports the annotations, builds the release,
then writes the SHA-256 of every file of the run folder to a JSON digest. Files that hold
wall-clock times or machine facts (logs, the review database, run summaries, done markers,
lock files) are listed apart under `volatile` and not compared; JSON and Parquet files are
also hashed without their wall-clock fields (`CLOCK_KEYS`: a step's wall time, a review's
time stamps), and a file that differs only there is reported as such.

    .venv/bin/python benchmarks/output_digest.py -c configs/smoke.yaml --out before.json
    .venv/bin/python benchmarks/output_digest.py --compare before.json after.json
    .venv/bin/python benchmarks/output_digest.py --compare-subset BEFORE_RUN AFTER_RUN

`--compare-subset` compares two run folders where AFTER ran a subset of BEFORE's units (fewer
tasks, same seed and settings: an episode's outputs depend only on what identifies it):
every file of AFTER must be byte-identical to BEFORE's (or differ only in wall-clock
fields), a Parquet table's rows must be among BEFORE's rows, a text list's lines among its
lines (`.jsonl`, SHA256SUMS); what summarizes the whole set (the dataset card, its figure)
is listed apart.

The review step only talks HTTP and the CLI, so the same script drives the code before and
after a refactor of the internals. Exit 1 when `--compare` finds a difference.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
import uuid
from pathlib import Path

import yaml
from rich.console import Console

console = Console()
REPO = Path(__file__).resolve().parents[1]
# the CLI of the checkout this script lives in (the editable install may point elsewhere)
RECOVER = [sys.executable, "-c", f"import sys; sys.path.insert(0, {str(REPO)!r}); from pipeline.cli import app; app()"]
VOLATILE = re.compile(r"(\.log$|\.sqlite|\.lock$|summary\.json$|/_done/|done\.json$|config\.resolved\.yaml$"
                      r"|\.sqlite-wal$|\.sqlite-shm$|report\.json$|/bench/)")


def recover(*args: str, cwd: Path = REPO) -> str:
    exe = [*RECOVER, *args]
    r = subprocess.run(exe, cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0:
        console.print(r.stdout[-3000:], r.stderr[-3000:])
        raise SystemExit(f"recover {' '.join(args)} failed with {r.returncode}")
    return r.stdout


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def call(base: str, token: str, method: str, path: str, body: dict | None = None) -> dict:
    req = urllib.request.Request(base + path, method=method, data=json.dumps(body).encode() if body is not None else None,
                                 headers={"Authorization": f"Bearer {token}", "Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=60) as r:
        return json.loads(r.read())


def review_all(config: Path, n_reviewers: int) -> int:
    """Every reviewer accepts every proposal (quarantined items are flagged); returns decisions."""
    tokens = []
    for i in range(n_reviewers):
        out = recover("review", "add-reviewer", f"digest_reviewer_{i}", "-c", str(config))
        tokens.append(re.search(r"token: (\S+)", out).group(1))
    port = free_port()
    server = subprocess.Popen([*RECOVER, "review", "serve", "-c", str(config),
                               "--host", "127.0.0.1", "--port", str(port), "--workers", "1"], cwd=REPO,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    base, n = f"http://127.0.0.1:{port}", 0
    try:
        for _ in range(200):
            try:
                urllib.request.urlopen(base + "/", timeout=1)
                break
            except OSError:
                time.sleep(0.2)
        for token in tokens:
            while (item := call(base, token, "POST", "/api/queue/next")["item"]) is not None:
                iid = item["id"] if isinstance(item, dict) else item
                view = call(base, token, "GET", f"/api/items/{iid}")
                body = {"decision": "flag", "reason": "quarantined"} if view.get("quarantined") else {"decision": "accept"}
                call(base, token, "POST", f"/api/items/{iid}/review",
                     {**body, "version": view.get("version", 0), "idempotency_key": uuid.uuid4().hex})
                n += 1
    finally:
        server.terminate()
        server.wait(timeout=30)
    return n


# wall-clock fields inside otherwise deterministic files: compared with these removed
CLOCK_KEYS = {"wall_time_s", "at", "finalized_at", "built_at", "created_at", "updated_at", "latency_s"}


def _strip(x):
    if isinstance(x, dict):
        return {k: _strip(v) for k, v in x.items() if k not in CLOCK_KEYS}
    if isinstance(x, list):
        return [_strip(v) for v in x]
    if isinstance(x, str) and x[:1] in "{[":
        try:
            return _strip(json.loads(x))
        except ValueError:
            return x
    return x


def clock_free_hash(p: Path) -> str | None:
    """Hash of a JSON or Parquet file without its wall-clock fields (None for other files)."""
    if p.suffix == ".json":
        try:
            data = json.loads(p.read_text())
        except ValueError:
            return None
        return hashlib.sha256(json.dumps(_strip(data), sort_keys=True).encode()).hexdigest()
    if p.suffix == ".parquet":
        import pyarrow.parquet as pq

        t = pq.read_table(p)
        rows = _strip(t.drop_columns([c for c in t.column_names if c in CLOCK_KEYS]).to_pylist())
        return hashlib.sha256((t.schema.to_string() + json.dumps(rows, sort_keys=True, default=str)).encode()).hexdigest()
    return None


def digest(run: Path) -> dict:
    files, clock_free, volatile = {}, {}, []
    for p in sorted(run.rglob("*")):
        if not p.is_file():
            continue
        rel = p.relative_to(run).as_posix()
        if VOLATILE.search("/" + rel):
            volatile.append(rel)
            continue
        files[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
        if (h := clock_free_hash(p)) is not None:
            clock_free[rel] = h
    return {"files": files, "clock_free": clock_free, "volatile": volatile}


def compare(a_path: Path, b_path: Path) -> int:
    da, db = json.loads(a_path.read_text()), json.loads(b_path.read_text())
    a, b = da["files"], db["files"]
    ca, cb = da.get("clock_free", {}), db.get("clock_free", {})
    only_a, only_b = sorted(set(a) - set(b)), sorted(set(b) - set(a))
    raw_diff = sorted(k for k in set(a) & set(b) if a[k] != b[k])
    clock = [k for k in raw_diff if k in ca and ca.get(k) == cb.get(k)]
    diff = [k for k in raw_diff if k not in clock]
    groups: dict[str, int] = {}
    for k in a:
        g = "/".join(k.split("/")[:2])
        groups[g] = groups.get(g, 0) + 1
    console.print(f"{len(a)} files in {a_path.name}, {len(b)} in {b_path.name}; by folder: {groups}")
    for name, ks in (("only before", only_a), ("only after", only_b), ("different only in wall-clock fields", clock),
                     ("different", diff)):
        console.print(f"{name}: {len(ks)}")
        for k in ks[:40]:
            console.print(f"  {k}")
    same = not (only_a or only_b or diff)
    console.print("[green]byte-identical[/]" if same else "[red]outputs differ[/]")
    return 0 if same else 1


SET_LEVEL = re.compile(r"(^|/)(README\.md|figures/.*\.png|model_vs_truth\.json|agreement\.(json|png))$")


def _rows(p: Path) -> tuple[str, set[str]]:
    import pyarrow.parquet as pq

    t = pq.read_table(p)
    rows = _strip(t.drop_columns([c for c in t.column_names if c in CLOCK_KEYS]).to_pylist())
    return t.schema.remove_metadata().to_string(), {json.dumps(r, sort_keys=True, default=str) for r in rows}


def compare_subset(before: Path, after: Path) -> int:
    """AFTER ran a subset of BEFORE's units: every AFTER file is BEFORE's, or a subset of it."""
    kinds: dict[str, list[str]] = {k: [] for k in ("identical", "wall-clock only", "rows among before's",
                                                    "lines among before's", "set-level", "only after", "different")}
    for p in sorted(after.rglob("*")):
        rel = p.relative_to(after).as_posix()
        if not p.is_file() or VOLATILE.search("/" + rel):
            continue
        q = before / rel
        if not q.is_file():
            kinds["only after"].append(rel)
        elif p.read_bytes() == q.read_bytes():
            kinds["identical"].append(rel)
        elif (h := clock_free_hash(p)) is not None and h == clock_free_hash(q):
            kinds["wall-clock only"].append(rel)
        elif p.suffix == ".parquet" and (ra := _rows(p))[0] == (rb := _rows(q))[0] and ra[1] <= rb[1]:
            kinds["rows among before's"].append(f"{rel} ({len(ra[1])} of {len(rb[1])} rows)")
        elif (p.suffix == ".jsonl" or p.name == "SHA256SUMS") and \
                set(p.read_text().splitlines()) <= set(q.read_text().splitlines()):
            kinds["lines among before's"].append(rel)
        elif SET_LEVEL.search(rel):
            kinds["set-level"].append(rel)
        else:
            kinds["different"].append(rel)
    n_before = sum(1 for p in before.rglob("*") if p.is_file() and not VOLATILE.search("/" + p.relative_to(before).as_posix()))
    console.print(f"{sum(map(len, kinds.values()))} files in {after} (a subset run), {n_before} in {before}")
    for name, ks in kinds.items():
        console.print(f"{name}: {len(ks)}")
        if name != "identical":
            for k in ks[:40]:
                console.print(f"  {k}")
    by_folder: dict[str, int] = {}
    for k in kinds["identical"] + kinds["wall-clock only"]:
        g = "/".join(k.split("/")[:1])
        by_folder[g] = by_folder.get(g, 0) + 1
    console.print(f"identical (incl. wall-clock only) by folder: {by_folder}")
    same = not (kinds["different"] or kinds["only after"])
    console.print("[green]every file of the subset run is the full run's[/]" if same else "[red]outputs differ[/]")
    return 0 if same else 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-c", "--config", type=Path)
    ap.add_argument("--out", type=Path, help="digest JSON to write")
    ap.add_argument("--reviewers", type=int, default=2)
    ap.add_argument("--fresh", action="store_true", help="delete the run folder first")
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("BEFORE", "AFTER"))
    ap.add_argument("--compare-subset", nargs=2, type=Path, metavar=("BEFORE_RUN", "AFTER_RUN"))
    ap.add_argument("--digest-only", type=Path, metavar="RUN", help="digest an existing run folder, run nothing")
    a = ap.parse_args()
    if a.compare:
        return compare(*a.compare)
    if a.compare_subset:
        return compare_subset(*a.compare_subset)
    if a.digest_only:
        d = digest(a.digest_only)
        a.out.write_text(json.dumps({**d, "run": str(a.digest_only)}, indent=1))
        console.print(f"{len(d['files'])} files digested -> {a.out}")
        return 0
    cfg = yaml.safe_load(a.config.read_text())
    run = Path(cfg["run"]["output_dir"])
    run = run if run.is_absolute() else REPO / run
    if a.fresh and run.exists():
        shutil.rmtree(run)
    t0 = time.perf_counter()
    for stage in ("stage1", "stage2", "stage3"):
        console.print(f"{stage} ...")
        recover(stage, "-c", str(a.config.resolve()))
    n = review_all(a.config.resolve(), a.reviewers)
    console.print(f"{n} decisions")
    recover("review", "export", "-c", str(a.config.resolve()))
    recover("release", "-c", str(a.config.resolve()))
    d = digest(run)
    d.update(config=str(a.config), commit=subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True,
                                                         text=True).stdout.strip(), seconds=round(time.perf_counter() - t0))
    a.out.write_text(json.dumps(d, indent=1))
    console.print(f"{len(d['files'])} files digested ({len(d['volatile'])} volatile) -> {a.out} in {d['seconds']} s")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    sys.exit(main())
