"""The simstate family behind the labeler protocols (`pipeline.labelers.base`): no model, the
rules of `localizer` (onset from events) and `characterizer` (level, category, action).

- `SimstateLocalizer`: an Episode's evidence -> Onset (fail_step, fail_time_s = step /
  control_hz, every event), or reason `no_failure_found` with the idle `fallback_step`, or
  `missing_evidence` when the episode came without evidence.
- `SimstateCharacterizer`: a Localization + its evidence -> Characterization; the evidence is
  read from `stage2/evidence/<suite>/<task>/<episode_id>.parquet` of the run folder unless the
  caller supplies it (`evidence_for`, e.g. the benchmark that measured it without writing).
  A missing or malformed evidence file is a stage-3 QuarantineEntry, never an exception.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from pipeline.errors import EpisodeError
from pipeline.evidence import Evidence
from pipeline.labelers.base import CharacterizeOutcome, Episode, Onset, Progress, Provenance
from pipeline.labelers.simstate import characterizer as rules
from pipeline.labelers.simstate.events import Thresholds
from pipeline.labelers.simstate.localizer import localize
from pipeline.layout import RunLayout, episode_key
from pipeline.records import Localization, QuarantineReason

SOURCE = "simstate"


class SimstateLocalizer:
    name = SOURCE

    def __init__(self, thresholds: Thresholds | None = None):
        self.thresholds = thresholds

    def localize(self, episodes: Sequence[Episode], progress: Progress | None = None) -> list[Onset]:
        out = []
        for ep in episodes:
            out.append(self._one(ep))
            if progress:
                progress()
        return out

    def _one(self, ep: Episode) -> Onset:
        if ep.evidence is None:
            return Onset(source=SOURCE, reason=QuarantineReason.missing_evidence, detail=f"{ep.folder}: no evidence measured")
        res = localize(ep.evidence, self.thresholds)
        if res.onset_step is None:
            return Onset(source=SOURCE, reason=QuarantineReason.no_failure_found, events=res.events, fallback_step=res.fallback_step)
        return Onset(source=SOURCE, fail_step=res.onset_step, fail_time_s=res.onset_step / ep.record.control_hz,
                     events=res.events)

    def close(self) -> None:
        pass


class SimstateCharacterizer:
    name = SOURCE

    def __init__(self, run_dir: Path, evidence_for: Callable[[Localization], Evidence] | None = None):
        from pipeline.evidence import read_evidence

        self.run_dir = Path(run_dir)
        self._read = read_evidence
        self._evidence_for = evidence_for

    def _path(self, loc: Localization) -> Path:
        return RunLayout(self.run_dir).stage2.evidence_of_key(episode_key(loc.suite, loc.task, loc.episode_id))

    def _one(self, loc: Localization) -> CharacterizeOutcome:
        path = self._path(loc)
        try:
            if self._evidence_for is not None:
                ev = self._evidence_for(loc)
            elif not path.is_file():
                raise EpisodeError(QuarantineReason.missing_evidence, f"{path}: no such file")
            else:
                ev = self._read(path)
            return rules.characterize(loc, ev)
        except EpisodeError as e:
            return Provenance(source=SOURCE).quarantine(loc.key, "stage3", e.reason, e.detail[:2000])
        except (ValueError, OSError, KeyError, IndexError) as e:  # a malformed evidence file
            detail = f"{path}: {type(e).__name__}: {e}"
            return Provenance(source=SOURCE).quarantine(loc.key, "stage3", QuarantineReason.bad_evidence, detail[:2000])

    def characterize(self, locs: Sequence[Localization], progress: Progress | None = None) -> list[CharacterizeOutcome]:
        out: list[CharacterizeOutcome] = []
        for loc in locs:
            out.append(self._one(loc))
            if progress:
                progress()
        return out

    def close(self) -> None:
        pass
