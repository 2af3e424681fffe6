"""Stage 2 work unit: the pending failed episodes of one task, run in one worker process.

Input: a `TaskUnit` (picklable). The worker builds the task's environment once (through a
per-process `EnvCache`), runs `process_episode` for each episode not yet done, marks each
done after its outputs exist, and emits one progress event per episode. A per-episode
EpisodeError has already become a quarantine entry; any other error of one episode (not a
FatalError) becomes an `episode_error` entry too, and the unit goes on with the next episode.
The done marker records the inputs' fingerprint (layout.fingerprint): a changed input is done
again. An `episode_error` gets no marker, so the next run tries it again.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pipeline.atomic import Completions, write_json
from pipeline.config import Stage2Config
from pipeline.errors import FatalError
from pipeline.labelers.base import Onset
from pipeline.records import EpisodeRecord, QuarantineEntry, QuarantineReason

_CACHE = None  # per worker process: the last task's environment


@dataclass(frozen=True)
class TaskUnit:
    suite: str
    task: str
    episodes: tuple[str, ...]  # EpisodeRecord JSON
    run_dir: str
    stage2_cfg: str  # Stage2Config JSON


def _env_for(suite: str, task: str):
    global _CACHE
    from pipeline.sim import EnvCache, get_task

    if _CACHE is None:
        _CACHE = EnvCache(capacity=1)
    return _CACHE.get(get_task(suite, task))


def _set_aside(paths, rec: EpisodeRecord, e: Exception):
    from pipeline.stage2.episode import Outcome

    paths.abs(paths.localization(rec)).unlink(missing_ok=True)
    entry = QuarantineEntry(key=rec.key, stage="stage2", source="stage2", reason=QuarantineReason.episode_error,
                            detail=f"{type(e).__name__}: {e}"[:2000])
    write_json(paths.abs(paths.quarantine(rec)), entry.model_dump(mode="json"))
    return Outcome(key=rec.key, status="quarantine", reason=entry.reason)


def _stored_onset(paths, rec: EpisodeRecord, backend: str) -> Onset | None:
    """The VLM step's answer for `rec` (None for simstate, which localizes in the worker)."""
    if backend == "simstate":
        return None
    file = paths.abs(paths.vlm(rec))
    if not file.exists():
        return Onset(source=backend, reason=QuarantineReason.backend_error, detail="no stored VLM result")
    try:
        return Onset.model_validate_json(file.read_text())
    except ValueError as e:  # ValidationError included: this episode is set aside (episode_error), naming the file
        raise ValueError(f"{file}: not a stored VLM answer: {e}") from e


def process_task(unit: TaskUnit, emit) -> list[dict]:
    from pipeline.stage2.episode import process_episode
    from pipeline.layout import RunLayout
    from pipeline.stage2.layout import fingerprint, unit_id

    layout = RunLayout(Path(unit.run_dir))
    cfg = Stage2Config.model_validate_json(unit.stage2_cfg)
    paths = layout.stage2
    done = Completions(paths.root)
    env = _env_for(unit.suite, unit.task)
    results = []
    for raw in unit.episodes:
        rec = EpisodeRecord.model_validate_json(raw)
        inputs = fingerprint(layout.stage1.root, rec)  # before reading: a file changed meanwhile is redone
        try:
            vlm = _stored_onset(paths, rec, cfg.vlm.backend)
            out = process_episode(env, rec, layout.stage1.root, paths, cfg, vlm)
            done.mark_done(unit_id(rec), {"status": out.status, "reason": out.reason, "inputs": inputs})
        except FatalError:
            raise
        except Exception as e:  # one episode's surprise must not cost the task's other episodes
            out = _set_aside(paths, rec, e)
        row = out.__dict__.copy()
        results.append(row)
        emit({"episode": rec.key, **row})
    return results
