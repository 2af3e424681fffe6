"""The VLM family behind the labeler protocols (`pipeline.labelers.base`): an `openai` or
`transformers` backend asked about the agentview video, answers read by the loss-free parser.

- `VLMLocalizer`: Episodes -> Onset: `fail_time_s` (seconds from video start, checked against
  the video's duration), or a `reason`: `no_video`, `backend_error` (the request failed for
  good) or the parser's quarantine reason. Every answer keeps the backend's provenance.
- `VLMCharacterizer`: Localizations -> Characterization, or a stage-3 QuarantineEntry
  (`missing_video`, `backend_error` or the parser's reason) with the raw text.
Both take an existing backend (so one model serves both, as in the benchmark) or build the
configured one; `close()` closes a backend they built or were given.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from pipeline.config import VLMConfig
from pipeline.errors import FatalError
from pipeline.labelers.base import CharacterizeOutcome, Episode, Onset, Progress, Provenance
from pipeline.labelers.vlm.backends import VLMBackend, VLMRequest, VLMResult, make_backend
from pipeline.layout import RunLayout
from pipeline.records import Characterization, Localization, QuarantineReason

CAMERA = "agentview"  # the camera the VLM sees, for localization (stage2.vlm_step) and characterization

def _duration(result: VLMResult, ep: Episode) -> float:
    """What the model saw: the sampled video, else the frame table, else the steps."""
    if result.video is not None:
        return float(result.video.duration_s)
    if ep.frames is not None and ep.frames.num_rows:
        return float(max(ep.frames.column("time_s").to_pylist()))
    return ep.record.steps / ep.record.control_hz


def onset_of(result: VLMResult, ep: Episode) -> Onset:
    """A localization result as an Onset (the parser decides whether the answer is usable)."""
    from pipeline.labelers.vlm.parse import parse_localization
    from pipeline.labelers.vlm.schemas import Quarantine

    trace = {**Provenance.of(result).model_dump(), "latency_s": result.latency_s}
    if result.error:
        return Onset(**trace, reason=QuarantineReason.backend_error, detail=result.error)
    answer = parse_localization(result, _duration(result, ep))
    if isinstance(answer, Quarantine):
        return Onset(**trace, reason=answer.reason, detail=answer.detail)
    return Onset(**trace, fail_time_s=float(answer.fail))


def _run(backend: VLMBackend, requests: list[VLMRequest], progress: Progress | None) -> list[VLMResult]:
    """The backend's results, one per request: a backend that lost or added one would shift
    every later answer onto the wrong episode, so that stops the run."""
    if not requests:
        return []
    results = backend.run(requests, progress=(lambda _r: progress()) if progress else None)
    if len(results) != len(requests):
        raise FatalError(f"{backend.name} backend: {len(results)} results for {len(requests)} requests; "
                         "answers cannot be matched to episodes")
    return results


class VLMLocalizer:
    def __init__(self, cfg: VLMConfig, backend: VLMBackend | None = None):
        self.backend = backend if backend is not None else make_backend(cfg)
        self.name = self.backend.name

    def localize(self, episodes: Sequence[Episode], progress: Progress | None = None) -> list[Onset]:
        out: list[Onset | None] = [None] * len(episodes)
        asked, requests = [], []
        for i, ep in enumerate(episodes):
            if ep.video is None:
                out[i] = Onset(source=self.name, reason=QuarantineReason.no_video, detail=f"no agentview video in {ep.folder}")
                continue
            requests.append(VLMRequest(task="localize", video=ep.video, instruction=ep.record.instruction,
                                       frames_table=ep.frames, key=ep.record.key))
            asked.append(i)
        for i, res in zip(asked, _run(self.backend, requests, progress), strict=True):
            out[i] = onset_of(res, episodes[i])
        return out  # type: ignore[return-value]  # every slot is filled above

    def close(self) -> None:
        self.backend.close()


class VLMCharacterizer:
    def __init__(self, cfg: VLMConfig, run_dir: Path, backend: VLMBackend | None = None):
        self.backend = backend if backend is not None else make_backend(cfg)
        self.name = cfg.backend
        self.run_dir = Path(run_dir)

    def _quarantine(self, loc: Localization, reason: QuarantineReason, detail: str, prov: Provenance | None = None):
        prov = prov or Provenance(source=self.name)
        return prov.quarantine(loc.key, "stage3", reason, detail[:2000])

    def characterize(self, locs: Sequence[Localization], progress: Progress | None = None) -> list[CharacterizeOutcome]:
        import pyarrow.parquet as pq

        from pipeline.labelers.vlm.parse import parse_characterization
        from pipeline.labelers.vlm.schemas import Quarantine

        requests, order = [], []
        out: list[CharacterizeOutcome | None] = [None] * len(locs)
        for i, loc in enumerate(locs):
            files = RunLayout(self.run_dir).stage1.episode_of_key(loc.key)
            video = files.video(CAMERA)
            if not video.is_file():
                out[i] = self._quarantine(loc, QuarantineReason.missing_video, f"{video}: no such file")
                continue
            frames = files.frames
            requests.append(VLMRequest(task="characterize", video=video, instruction=loc.instruction,
                                       fail_time_s=loc.fail_time_s, key=loc.key,
                                       frames_table=pq.read_table(frames) if frames.is_file() else None))
            order.append(i)
        for i, res in zip(order, _run(self.backend, requests, progress), strict=True):
            loc = locs[i]
            ans = parse_characterization(res)
            if isinstance(ans, Quarantine):
                reason = QuarantineReason.backend_error if res.error else ans.reason
                prov = Provenance.of(res, source=self.name).model_copy(update={"raw_text": res.raw_text or ans.raw_text})
                out[i] = self._quarantine(loc, reason, res.error or ans.detail, prov)
            else:
                out[i] = Characterization(key=loc.key, recovery_level=ans.recovery_level,
                                          failure_category=ans.failure_category, recovery_action=ans.recovery_action,
                                          **Provenance.of(res, source=self.name).model_dump())
        return out  # type: ignore[return-value]  # every slot is filled above

    def close(self) -> None:
        self.backend.close()
