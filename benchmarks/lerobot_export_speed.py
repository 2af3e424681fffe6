"""Wall and CPU time of `recover export-lerobot`'s recoveries dataset per demo: 1 vs 2 workers,
standard vs fast render quality, side by side in one run.

    nice -n 10 .venv/bin/python benchmarks/lerobot_export_speed.py [--run RUN] [--demos 4] [--per-scene 2] [--work DIR]

Copies the first `--demos` recovery demos of RUN (by scene id, at most `--per-scene` each) with
their states, step logs and RUN's release into a scratch run under `--work` (RUN is only
read), then exports that run's `recoveries` dataset once per option, each into its own
fresh folder, through the same `lerobot_export.run` the CLI calls. Reports seconds per demo
and milliseconds per frame, wall and CPU (this process and its workers, llvmpipe's threads
included: CPU time holds on a busy machine, wall time does not). Also checks that the
1- and 2-worker standard exports are the same files byte for byte, and gives the mean
pixel difference (decoded frames, 0-255) of the fast export against the standard one.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

OPTIONS = {"standard, 1 worker": ("standard", 1), "standard, 2 workers": ("standard", 2),
           "fast, 1 worker": ("fast", 1), "fast, 2 workers": ("fast", 2)}


def scratch_run(src: Path, work: Path, n: int, per_scene: int):
    """A run folder under `work` holding the first `n` demos of `src` (at most `per_scene` of a
    scene) and its release."""
    from pipeline.config import load_config
    from pipeline.layout import EpisodeFiles, RunLayout
    from pipeline.release.recovery_demos import read_demos, write_demos

    cfg = load_config(src / "config.resolved.yaml")
    demos, per = [], {}
    for d in sorted(read_demos(RunLayout.of(cfg).recoveries.demos), key=lambda d: (d.scene_id, d.demo_index)):
        if len(demos) < n and per.get(d.scene_id, 0) < per_scene:
            demos.append(d)
            per[d.scene_id] = per.get(d.scene_id, 0) + 1
    run = work / "run"
    shutil.rmtree(run, ignore_errors=True)
    new = cfg.model_copy(update={"run": cfg.run.model_copy(update={"output_dir": run})})
    old_rec, new_rec = RunLayout.of(cfg).recoveries.root, RunLayout.of(new).recoveries.root
    for d in demos:  # only what the export reads: states and step log
        old_files, new_files = EpisodeFiles(old_rec / d.path), EpisodeFiles(new_rec / d.path)
        new_files.dir.mkdir(parents=True, exist_ok=True)
        for which in ("states", "steps"):
            shutil.copy2(getattr(old_files, which), getattr(new_files, which))
    write_demos(RunLayout.of(new).recoveries.demos, demos)
    shutil.copytree(RunLayout.of(cfg).release.root, RunLayout.of(new).release.root)
    return new, demos


def cpu_s() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def decoded(path: Path) -> np.ndarray:
    import av

    with av.open(str(path)) as c:
        return np.stack([f.to_ndarray(format="rgb24") for f in c.decode(c.streams.video[0])])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, default=Path("/work/runs/final100"))
    ap.add_argument("--demos", type=int, default=4)
    # 2 per scene: with 2 workers each scene's model is one shard of equal size (the export's
    # shards follow models, so a sample of unequal scenes would measure the imbalance instead)
    ap.add_argument("--per-scene", type=int, default=2)
    ap.add_argument("--work", type=Path, default=Path("/tmp/lerobot_export_bench"))
    args = ap.parse_args()
    from pipeline.release.lerobot_export import run as export

    cfg, demos = scratch_run(args.run, args.work, args.demos, args.per_scene)
    frames = sum(d.steps for d in demos)
    print(f"{len(demos)} demos from {len({d.scene_id for d in demos})} scenes, {frames} frames, "
          f"{cfg.release.lerobot_image_size} px, 2 cameras; os.cpu_count()={os.cpu_count()}, "
          f"load average {os.getloadavg()[0]:.1f}")
    rows, outs = [], {}
    for name, (quality, workers) in OPTIONS.items():
        c = cfg.model_copy(update={
            "executor": cfg.executor.model_copy(update={"kind": "local", "workers": workers}),
            "release": cfg.release.model_copy(update={"lerobot_render_quality": quality})})
        out = args.work / "out" / name.replace(", ", "_").replace(" ", "")
        shutil.rmtree(out, ignore_errors=True)
        t0, c0 = time.perf_counter(), cpu_s()
        outs[name] = export(c, out, only=["recoveries"]) / "recoveries"
        wall, cpu = time.perf_counter() - t0, cpu_s() - c0
        rows.append(f"| {name} | {wall / len(demos):.1f} | {1000 * wall / frames:.0f} | {cpu / len(demos):.1f} "
                    f"| {os.getloadavg()[0]:.1f} |")
        print(rows[-1], flush=True)  # as it comes: a long run on a busy machine
    print("\n| option | wall s/demo | wall ms/frame | CPU s/demo | load after |\n|---|---|---|---|---|")
    print("\n".join(rows))

    a, b = outs["standard, 1 worker"], outs["standard, 2 workers"]
    files = sorted(str(p.relative_to(a)) for p in a.rglob("*") if p.is_file())
    same = files == sorted(str(p.relative_to(b)) for p in b.rglob("*") if p.is_file()) and all(
        (a / f).read_bytes() == (b / f).read_bytes() for f in files)
    print(f"\nstandard, 1 vs 2 workers: {len(files)} files, byte-identical: {same}")
    fa, fb = outs["fast, 1 worker"], outs["fast, 2 workers"]
    same_fast = all((fa / f).read_bytes() == (fb / f).read_bytes() for f in files)
    print(f"fast, 1 vs 2 workers: byte-identical: {same_fast}")
    fast = outs["fast, 1 worker"]
    diffs = [np.abs(decoded(p).astype(int) - decoded(fast / p.relative_to(a)).astype(int)).mean()
             for p in sorted(a.rglob("*.mp4"))]
    print(f"fast vs standard: mean pixel difference {np.mean(diffs):.2f}/255 (max over videos {np.max(diffs):.2f})")


if __name__ == "__main__":
    main()
