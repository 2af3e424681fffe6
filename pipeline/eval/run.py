"""`recover eval`: run the recovery evaluation and write records, metrics and the report.

Inputs: a validated `Config` (section `eval`), the scenes (`plan.default_scenes_dir`) and,
for RD, the stage-1 rollouts they were cut from.
Outputs under `<run.output_dir>/eval/`: `config.resolved.yaml`, `trials/<unit>.parquet`
and `_done/<unit>.done` per trial, `quarantine.jsonl` (trials that could not run, with the
reason), `episodes.parquet` (all rows of this plan), `metrics.json`, `report.md` + PNGs.

Invariants: resumable: a trial's row is written atomically, then its marker; a rerun skips
marked trials and re-gathers. The trials run as a Stage (stage.py) on the configured
executor; each worker's WorkerContext keeps one environment (the current task's) and one
instance of each policy alive across its trials.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from pipeline.atomic import write_text
from pipeline.config import Config, save_resolved
from pipeline.errors import FatalError
from pipeline.eval.plan import default_scenes_dir
from pipeline.eval.records import EvalEpisode, read_episodes, write_episodes
from pipeline.eval.scenes import choose_split, find_scenes
from pipeline.eval.stage import EvalStage
from pipeline.layout import EvalLayout, RunLayout

WORKER_ENV = {"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}


def gather(out: Path, unit_ids: list[str]) -> list[EvalEpisode]:
    rows: list[EvalEpisode] = []
    for uid in unit_ids:
        p = EvalLayout(out).trial(uid)
        if p.is_file():
            rows += read_episodes(p)
    return rows


def run(cfg: Config) -> Path:
    for k, v in WORKER_ENV.items():
        os.environ.setdefault(k, v)
    layout = RunLayout.of(cfg).eval
    out = layout.root
    out.mkdir(parents=True, exist_ok=True)
    save_resolved(cfg, out)
    scenes_dir = default_scenes_dir(cfg)
    try:
        scenes, problems = find_scenes(scenes_dir)
    except (FileNotFoundError, ValueError) as e:
        raise FatalError(f"eval: cannot read scenes: {e}") from None
    found = len(scenes)
    scenes, split_note = choose_split(scenes, cfg.eval.split)
    if found and not scenes:
        raise FatalError(f"eval: none of the {found} scenes under {scenes_dir} is in the {cfg.eval.split} split "
                         f"(choose another with `recover eval --split train|all` or eval.split)")
    if cfg.eval.max_scenes is not None:
        scenes = scenes[: cfg.eval.max_scenes]
    if not scenes:
        raise FatalError(f"eval: no scenes under {scenes_dir} (run stage 2 or release first, or set eval.scenes_dir)")
    from pipeline.executors import make_executor
    from pipeline.runner import Runner

    stage = EvalStage(cfg, str(out), scenes)
    trials = stage.units(cfg)
    problems += stage.problems
    runner = Runner(make_executor(cfg.executor, worker_env=WORKER_ENV))
    todo = runner.pending(stage, trials)
    if todo:
        runner.execute(stage, todo)
    episodes = gather(out, [t.unit_id for t in trials])
    write_episodes(layout.episodes, episodes)
    planned = {t.unit_id for t in trials}
    quarantine = [p for p in sorted(layout.quarantine_dir.glob("*.json")) if p.stem in planned] \
        if layout.quarantine_dir.is_dir() else []
    write_text(layout.quarantine_log, "".join(json.dumps(json.loads(p.read_text())) + "\n" for p in quarantine))
    from pipeline.eval.records import read_rows
    from pipeline.eval.report import write_report

    write_report(read_rows(layout.episodes), cfg.eval, out, scenes_dir=scenes_dir, problems=problems,
                 planned=len(trials), split_note=split_note)
    return out
