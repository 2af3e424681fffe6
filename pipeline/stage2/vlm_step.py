"""The one place stage 2 calls a VLM (`openai` / `transformers` backends of pipeline.vlm).

Input: the failed episodes still to do and the run config. For each episode the backend
is asked when the failure began (agentview video + instruction + stage 1's frame table, so
times are true times); the answer goes through the loss-free parser. Output, per episode,
`stage2/vlm/<suite>/<task>/<episode_id>.json`:
    {"source", "model", "prompt_name", "prompt_hash", "raw_text", "latency_s",
     "fail_time_s"}                      -- a usable answer, or
    {..., "reason", "detail"}           -- the parser's / backend's quarantine reason.
The episode workers read these files (pipeline/stage2/stage.py). Requests go in batches of
`BATCH` so a crash loses at most one batch; episodes with a stored file are skipped.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from pipeline.atomic import write_json
from pipeline.config import Config
from pipeline.records import EpisodeRecord
from pipeline.stage2.layout import Stage2Paths

BATCH = 32


def _duration(result, rec: EpisodeRecord, frames) -> float:
    if result.video is not None:
        return float(result.video.duration_s)
    if frames is not None and frames.num_rows:
        return float(max(frames.column("time_s").to_pylist()))
    return rec.steps / rec.control_hz


def _stored(result, rec: EpisodeRecord, frames) -> dict:
    from pipeline.vlm.parse import parse_localization
    from pipeline.vlm.schemas import Quarantine

    out = {"source": result.backend, "model": result.model, "prompt_name": result.prompt_name,
           "prompt_hash": result.prompt_hash, "raw_text": result.raw_text, "latency_s": result.latency_s}
    if result.error:
        return {**out, "reason": "backend_error", "detail": result.error}
    answer = parse_localization(result, _duration(result, rec, frames))
    if isinstance(answer, Quarantine):
        return {**out, "reason": answer.reason.value, "detail": answer.detail}
    return {**out, "fail_time_s": float(answer.fail)}


def run_vlm(cfg: Config, episodes: list[EpisodeRecord], paths: Stage2Paths,
            on_result: Callable[[], None] | None = None) -> int:
    """Localize every episode without a stored VLM result; return how many were asked."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pipeline.vlm.backends import VLMRequest, make_backend

    stage1 = cfg.out / "stage1"
    todo = [r for r in episodes if not paths.abs(paths.vlm(r)).exists()]
    if not todo:
        return 0
    backend = make_backend(cfg.stage2.vlm)
    asked = 0
    try:
        for i in range(0, len(todo), BATCH):
            batch, requests, frames = [], [], {}
            for rec in todo[i : i + BATCH]:
                folder = stage1 / rec.path
                video = rec.videos.get("agentview")
                if not video or not (folder / video).exists():
                    write_json(paths.abs(paths.vlm(rec)), {"source": backend.name, "reason": "no_video",
                                                           "detail": f"no agentview video in {folder}"})
                    continue
                fp = folder / "frames.parquet"
                try:
                    frames[rec.key] = pq.read_table(fp) if fp.exists() else None
                except (pa.ArrowException, OSError) as e:  # truncated: the episode worker sets it aside
                    write_json(paths.abs(paths.vlm(rec)), {"source": backend.name, "reason": "stage1_bad_frames",
                                                           "detail": f"{fp}: unreadable ({e})"})
                    continue
                requests.append(VLMRequest(task="localize", video=Path(folder / video), instruction=rec.instruction,
                                           frames_table=frames[rec.key], key=rec.key))
                batch.append(rec)
            results = backend.run(requests, progress=(lambda _r: on_result()) if on_result else None)
            for rec, res in zip(batch, results, strict=True):
                write_json(paths.abs(paths.vlm(rec)), _stored(res, rec, frames[rec.key]))
            asked += len(batch)
    finally:
        backend.close()
    return asked
