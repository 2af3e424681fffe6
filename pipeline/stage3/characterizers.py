"""Characterizers behind one call: localizations in, Characterization or QuarantineEntry out.

- simstate (default): rules over the stage-2 evidence (`pipeline.characterize.simstate`).
- openai | transformers: the stage-2 VLM backends with the categorization prompt
  (`pipeline.vlm.backends.make_backend(cfg.stage3.vlm)`), answers parsed by the same
  loss-free parser (`pipeline.vlm.parse.parse_characterization`).
Invariants: one result per input, in input order; a failure of one episode (unparseable
answer, backend error, missing evidence) is a QuarantineEntry with stage "stage3" and the
raw text, never an exception; a misconfiguration (no model, bad prompt) raises before work.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from pipeline.config import Config
from pipeline.errors import EpisodeError
from pipeline.records import Characterization, Localization, QuarantineEntry, QuarantineReason

Outcome = Characterization | QuarantineEntry


def _quarantine(loc: Localization, source: str, reason: str, detail: str, raw: str | None = None,
                model: str | None = None, prompt_name: str | None = None, prompt_hash: str | None = None) -> QuarantineEntry:
    return QuarantineEntry(key=loc.key, stage="stage3", source=source, reason=reason, detail=detail[:2000],
                           raw_text=raw, model=model, prompt_name=prompt_name, prompt_hash=prompt_hash)


class SimstateCharacterizer:
    name = "simstate"

    def __init__(self, cfg: Config):
        from pipeline.characterize import simstate
        from pipeline.evidence import read_evidence

        self._characterize, self._read = simstate.characterize, read_evidence
        self.run_dir = Path(cfg.out)

    def __call__(self, locs: list[Localization], progress: Callable[[], None] | None = None) -> list[Outcome]:
        out: list[Outcome] = []
        for loc in locs:
            path = self.run_dir / "stage2" / "evidence" / loc.suite / loc.task / f"{loc.episode_id}.parquet"
            try:
                if not path.is_file():
                    raise EpisodeError(QuarantineReason.missing_evidence, f"{path}: no such file")
                out.append(self._characterize(loc, self._read(path)))
            except EpisodeError as e:
                out.append(_quarantine(loc, "simstate", e.reason, e.detail))
            except (ValueError, OSError, KeyError, IndexError) as e:  # a malformed evidence file
                out.append(_quarantine(loc, "simstate", QuarantineReason.bad_evidence, f"{path}: {type(e).__name__}: {e}"))
            if progress:
                progress()
        return out


class VLMCharacterizer:
    def __init__(self, cfg: Config):
        from pipeline.vlm.backends import make_backend

        self.backend = make_backend(cfg.stage3.vlm)
        self.name = cfg.stage3.vlm.backend
        self.run_dir = Path(cfg.out)

    def __call__(self, locs: list[Localization], progress: Callable[[], None] | None = None) -> list[Outcome]:
        import pyarrow.parquet as pq

        from pipeline.vlm.backends import VLMRequest
        from pipeline.vlm.parse import parse_characterization
        from pipeline.vlm.schemas import Quarantine

        requests, order = [], []
        out: list[Outcome | None] = [None] * len(locs)
        for i, loc in enumerate(locs):
            suite, task, ep = loc.key.split("/", 2)
            ep_dir = self.run_dir / "stage1" / "episodes" / suite / task / ep
            video = ep_dir / "video_agentview.mp4"
            if not video.is_file():
                out[i] = _quarantine(loc, self.name, QuarantineReason.missing_video, f"{video}: no such file")
                continue
            frames = ep_dir / "frames.parquet"
            requests.append(VLMRequest(task="characterize", video=video, instruction=loc.instruction,
                                       fail_time_s=loc.fail_time_s, key=loc.key,
                                       frames_table=pq.read_table(frames) if frames.is_file() else None))
            order.append(i)
        results = self.backend.run(requests, progress=(lambda _r: progress()) if progress else None) if requests else []
        for i, res in zip(order, results):
            loc = locs[i]
            ans = parse_characterization(res)
            if isinstance(ans, Quarantine):
                reason = QuarantineReason.backend_error if res.error else ans.reason.value
                out[i] = _quarantine(loc, self.name, reason, res.error or ans.detail, res.raw_text or ans.raw_text,
                                     res.model, res.prompt_name, res.prompt_hash)
            else:
                out[i] = Characterization(key=loc.key, recovery_level=ans.recovery_level,
                                          failure_category=ans.failure_category, recovery_action=ans.recovery_action,
                                          source=self.name, model=res.model, prompt_name=res.prompt_name,
                                          prompt_hash=res.prompt_hash, raw_text=res.raw_text)
        return [o for o in out if o is not None]

    def close(self) -> None:
        self.backend.close()


def make_characterizer(cfg: Config):
    return SimstateCharacterizer(cfg) if cfg.stage3.vlm.backend == "simstate" else VLMCharacterizer(cfg)
