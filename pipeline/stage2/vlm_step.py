"""The one place stage 2 calls a VLM: the `openai` / `transformers` localizer of
`pipeline.labelers` (built by `registry.make_localizer`, used through the Localizer protocol).

Input: the failed episodes still to do and the run config. For each episode the backend
is asked when the failure began (agentview video + instruction + stage 1's frame table, so
times are true times); the answer goes through the loss-free parser. Output, per episode,
an `Onset` (pipeline.labelers.base) stored as `stage2/vlm/<suite>/<task>/<episode_id>.json`:
    {"source", "model", "prompt_name", "prompt_hash", "raw_text", "latency_s",
     "fail_time_s"}                      -- a usable answer, or
    {..., "reason", "detail"}           -- the parser's / backend's quarantine reason.
The episode workers read these files (pipeline/stage2/stage.py). Requests go in batches of
`BATCH` so a crash loses at most one batch; episodes with a stored file are skipped.
"""

from __future__ import annotations

from collections.abc import Callable

from pipeline.atomic import write_json
from pipeline.config import Config
from pipeline.labelers.base import Episode, Onset
from pipeline.layout import RunLayout, Stage2Layout
from pipeline.records import EpisodeRecord, QuarantineReason
from pipeline.rendered import require_current_frames

BATCH = 32


def run_vlm(cfg: Config, episodes: list[EpisodeRecord], paths: Stage2Layout,
            on_result: Callable[[], None] | None = None) -> int:
    """Localize every episode without a stored VLM result; return how many were asked."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pipeline.labelers.registry import make_localizer

    stage1 = RunLayout.of(cfg).stage1
    todo = [r for r in episodes if not paths.abs(paths.vlm(r)).exists()]
    if not todo:
        return 0
    require_current_frames([stage1.episode(r).frames for r in todo], f"stage 2's {cfg.stage2.vlm.backend} localizer")
    localizer = make_localizer(cfg.stage2.vlm)
    asked = 0
    try:
        for i in range(0, len(todo), BATCH):
            batch: list[Episode] = []
            for rec in todo[i : i + BATCH]:
                folder = stage1.episode(rec).dir
                video = stage1.video(rec, "agentview")
                if video is None or not video.exists():
                    batch.append(Episode(rec, folder))  # the localizer answers no_video
                    continue
                fp = stage1.episode(rec).frames
                try:
                    frames = pq.read_table(fp) if fp.exists() else None
                except (pa.ArrowException, OSError) as e:  # truncated: the episode worker sets it aside
                    bad = Onset(source=localizer.name, reason=QuarantineReason.stage1_bad_frames, detail=f"{fp}: unreadable ({e})")
                    write_json(paths.abs(paths.vlm(rec)), bad.stored())
                    continue
                batch.append(Episode(rec, folder, video, frames))
            for ep, onset in zip(batch, localizer.localize(batch, progress=on_result), strict=True):
                write_json(paths.abs(paths.vlm(ep.record)), onset.stored())
            asked += sum(ep.video is not None for ep in batch)
    finally:
        localizer.close()
    return asked
