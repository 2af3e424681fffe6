"""Certification of one release on the executors: 1 vs N local workers, and a Ray cluster losing a node.

Reads a built release (its `scenarios.parquet` and scene files, read only) and certifies
every scene with the release's own settings (`cfg.release`: expert, tries, horizon) through
the real path (`pipeline.release.certify.certify_all`: the `CertifyStage` run by the
`Runner`), each time into a fresh folder under `--out`:

- `local<N>` for each `--workers N`: wall time of each, the speed-up over the first, and
  whether the certificates are identical to each other and to the ones in the manifest
  (what the release build computed);
- `--stage2 RUN` certifies the scenes of a run's stage 2 (no release needed; the same scene
  files a release of them copies), without a manifest to compare with;
- with `--ray`: a local `ray.cluster_utils.Cluster` (a head that runs nothing and two
  one-CPU worker nodes); once a third of the scenes are done one worker node is removed.
  Shows that every scene got exactly one `done` event and one marker, the shards lost with
  the node were retried, and the certificates equal the local ones.

    .venv/bin/python benchmarks/certify_executors.py -c /work/runs/base100.yaml \\
        [--release DIR] [--workers 1 2] [--ray] [--out /work/runs/<name>/certify_executors]

Writes `results.json` to `--out`; exit 1 when certificates differ or a scene was not
certified exactly once.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import shutil
import sys
import threading
import time
from collections import Counter
from dataclasses import asdict
from pathlib import Path

from rich.console import Console
from rich.table import Table

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.config import load_config  # noqa: E402
from pipeline.layout import RunLayout  # noqa: E402
from pipeline.release.certify import Certificate, certify_all, scene_refs  # noqa: E402
from pipeline.release.manifest import MANIFEST_NAME, read_manifest  # noqa: E402

console = Console()
WORKER_ENV = {"PYTHONPATH": str(REPO), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def manifest_certificates(rows, refs) -> dict[str, Certificate]:
    """What the release build wrote into the manifest, as certificates by scene."""
    return {ref.unit: Certificate(r.certify_tries, r.certify_successes, r.certify_reason)
            for r, ref in zip(rows, refs) if r.certified is not None}


def stage2_scenes(run: Path):
    """Scenes straight from a run's stage-2 localizations (what a release of every localized
    episode, reviewed without moving an onset, would certify): the refs, no manifest."""
    from pipeline.layout import episode_key, parse_key, scene_unit
    from pipeline.records import Localization
    from pipeline.release.certify import SceneRef
    from pipeline.release.manifest import sha256_file

    root = RunLayout(run).stage2.root
    refs = []
    for f in sorted(RunLayout(run).stage2.localizations_dir.rglob("*.json")):
        loc = Localization.model_validate_json(f.read_text())
        suite, task, ep = parse_key(loc.key)
        bddl, state = root / loc.scene_bddl, root / loc.scene_state
        refs.append(SceneRef(suite, task, loc.instruction, bddl, state,
                             f"{sha256_file(bddl)[:16]}-{sha256_file(state)[:16]}",
                             scene_unit(episode_key(suite, task, ep), loc.scene_step)))
    return refs


def run_local(cfg, refs, folder: Path, workers: int) -> tuple[dict, float]:
    from pipeline.executors.local import LocalExecutor

    shutil.rmtree(folder, ignore_errors=True)
    t0 = time.perf_counter()
    certs = certify_all(refs, cfg, folder, cfg.release.certify_expert,
                        executor=LocalExecutor(workers, worker_env=WORKER_ENV), console=console)
    return certs, time.perf_counter() - t0


def run_ray(cfg, refs, folder: Path) -> dict:
    from ray.cluster_utils import Cluster

    from pipeline.executors.ray import RayExecutor
    from pipeline.release.certify import CertifyStage
    from pipeline.runner import Event, Runner

    shutil.rmtree(folder, ignore_errors=True)
    c = Cluster(initialize_head=True, head_node_args={
        "num_cpus": 0,  # the head runs nothing: both workers live on the two worker nodes
        "_system_config": {"health_check_initial_delay_ms": 0, "health_check_period_ms": 300,
                           "health_check_failure_threshold": 3},
    })
    done: Counter[str] = Counter()
    removed_after: list[int] = []
    try:
        nodes = [c.add_node(num_cpus=1) for _ in range(2)]
        c.wait_for_nodes()
        threshold = max(1, len(refs) // 3)

        def on_event(ev: Event) -> None:
            if ev.kind == "done":
                done[ev.unit] += 1
                if sum(done.values()) == threshold and not removed_after:
                    removed_after.append(threshold)
                    # off the event thread: removing a node blocks until its processes are gone
                    threading.Thread(target=c.remove_node, args=(nodes[1],)).start()

        stage = CertifyStage(cfg, refs, folder, cfg.release.certify_expert)
        t0 = time.perf_counter()
        stats = Runner(RayExecutor(workers=2, address=c.address, worker_env=WORKER_ENV), console=console).run(
            stage, cfg, on_event=on_event)
        wall = time.perf_counter() - t0
        certs = stage.certificates()
    finally:
        c.shutdown()
    markers = sorted(p.name for p in (folder / "_done").glob("*.done"))
    return {"certs": certs, "wall_s": wall, "done_events": dict(done), "markers": markers,
            "removed_after_done": removed_after[0] if removed_after else None,
            "retried": [e.model_dump() for e in stats.retried], "set_aside": [e.model_dump() for e in stats.set_aside]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-c", "--config", type=Path, required=True)
    ap.add_argument("--release", type=Path, help="release folder (default: the config's)")
    ap.add_argument("--stage2", type=Path, metavar="RUN", help="certify the stage-2 scenes of this run folder instead")
    ap.add_argument("--workers", type=int, nargs="*", default=[1, 2], help="local runs (none: --ray only)")
    ap.add_argument("--ray", action="store_true", help="also certify on a local Ray cluster losing a node")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    cfg = load_config(args.config)
    release = args.release or RunLayout.of(cfg).release.root
    out = args.out or RunLayout.of(cfg).root / "bench" / "certify_executors"
    if args.stage2:
        release, refs, reference = args.stage2 / "stage2", stage2_scenes(args.stage2), {}
    else:
        rows = read_manifest(release / MANIFEST_NAME)
        refs = scene_refs(rows, release)
        reference = manifest_certificates(rows, refs)
    console.print(f"{len(refs)} scenes of {release}; expert {cfg.release.certify_expert}, tries "
                  f"{cfg.release.certify_tries}, horizon {cfg.release.certify_horizon}; {os.cpu_count()} cpus, "
                  f"load {os.getloadavg()[0]:.1f}")
    result: dict = {"release": str(release), "scenes": len(refs), "cpus": os.cpu_count(), "runs": {}}
    ok = True
    certs_by_run: dict[str, dict] = {}
    for w in args.workers:
        certs, wall = run_local(cfg, refs, out / f"local{w}", w)
        certs_by_run[f"local{w}"] = certs
        result["runs"][f"local{w}"] = {"wall_s": round(wall, 1), "certificates": len(certs),
                                       "load_after": round(os.getloadavg()[0], 1)}
    if args.ray:
        r = run_ray(cfg, refs, out / "ray")
        certs_by_run["ray"] = r.pop("certs")
        once = set(r["done_events"].values()) == {1} and len(r["done_events"]) == len(refs) \
            and len(r["markers"]) == len(refs)
        result["runs"]["ray"] = {"wall_s": round(r["wall_s"], 1), "certificates": len(certs_by_run["ray"]),
                                 "every_scene_done_exactly_once": once, "removed_node_after_done": r["removed_after_done"],
                                 "retried": [(e["unit"], e["reason"]) for e in r["retried"]],
                                 "set_aside": [(e["unit"], e["reason"]) for e in r["set_aside"]]}
        ok &= once
    table = Table(title=f"certification of {len(refs)} scenes")
    for col in ("run", "wall s", "speed-up", "certificates", "= manifest", "= first run"):
        table.add_column(col)
    first = next(iter(certs_by_run))
    for name, certs in certs_by_run.items():
        same_manifest = certs == reference
        same_first = certs == certs_by_run[first]
        ok &= same_first and (same_manifest or not reference)
        run = result["runs"][name]
        run.update(same_as_manifest=same_manifest, same_as_first=same_first)
        if name.startswith("local"):
            run["speedup"] = round(result["runs"][first]["wall_s"] / run["wall_s"], 2)
        table.add_row(name, str(run["wall_s"]), str(run.get("speedup", "-")), str(len(certs)),
                      str(same_manifest), str(same_first))
    console.print(table)
    if "ray" in result["runs"]:
        console.print({k: v for k, v in result["runs"]["ray"].items() if k != "wall_s"})
    result["certified"] = sum(c.certified for c in certs_by_run[first].values())
    result["certificates"] = {k: asdict(v) for k, v in sorted(certs_by_run[first].items())}
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(result, indent=1) + "\n")
    console.print(f"{'[green]ok' if ok else '[red]MISMATCH'}[/] -> {out / 'results.json'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
