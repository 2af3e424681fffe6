"""What stage 3 reads from stages 1 and 2, and the review context built from it.

Inputs (run folder):
  stage2/localizations/<suite>/<task>/<episode_id>.json   records.Localization
  stage2/quarantine/**.json                                records.QuarantineEntry
  stage2/evidence/<suite>/<task>/<episode_id>.parquet      EVIDENCE_SCHEMA
  stage1/episodes/<suite>/<task>/<episode_id>/video_<camera>.mp4, frames.parquet
Outputs: `Unit`s, one per episode key: a localization, or the quarantine entry of an episode
with no localization. A localization stage 3 cannot use as it is becomes a quarantined unit
itself (a stage-3 QuarantineEntry naming the file, the field and the reason, one of
`INPUT_FAULTS`): a file that does not parse, a key that is not its suite/task/episode_id, a
fail_time_s that is NaN, negative or past the episode's end, a key another file claims too. Nothing is silently dropped.
Paths in the context are relative to the run folder (the server serves nothing else).
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

from pydantic import ValidationError

from pipeline.atomic import file_stamp
from pipeline.layout import RunLayout, episode_key, is_key, unit_id
from pipeline.records import Localization, QuarantineEntry, QuarantineReason
from pipeline.sim.render import CAMERAS


log = logging.getLogger("pipeline.stage3")
# what reading a media or table file that exists can raise when it is broken: pyarrow's
# ArrowInvalid and PyAV's InvalidDataError are ValueErrors, ArrowIOError an OSError, a
# missing column a KeyError, a video without a stream an IndexError; anything else is a bug
UNREADABLE = (OSError, ValueError, KeyError, IndexError)


def warn_unreadable(path: Path, e: Exception, effect: str) -> None:
    """Say which file could not be read and what the run does without it (on stderr)."""
    log.warning("stage 3: %s: unreadable (%s: %s); %s", path, type(e).__name__, e, effect)


# reasons of the units `collect` sets aside itself: a stage-2 file it cannot use as it is
INPUT_FAULTS = (QuarantineReason.unreadable, QuarantineReason.key_mismatch, QuarantineReason.duplicate_key,
                QuarantineReason.fail_time_not_finite, QuarantineReason.fail_time_negative,
                QuarantineReason.fail_time_beyond_episode)


@dataclass
class Unit:
    key: str
    localization: Localization | None = None
    quarantine: QuarantineEntry | None = None
    source: Path | None = None  # the stage-2 file this unit was read from
    instruction: str | None = None  # kept when a localization is set aside

    @property
    def unit_id(self) -> str:
        return unit_id(self.key)


def fingerprint(run_dir: Path, unit: Unit) -> str:
    """What a unit's stage-3 outcome is computed from: the bytes of its stage-2 file and the
    size + mtime of its evidence. The done marker records it; a corrected file is read again."""
    import hashlib

    h = hashlib.sha256()
    for path in (unit.source,) if unit.source else ():
        try:
            h.update(path.read_bytes())
        except OSError:
            h.update(b"missing")
    ev = RunLayout(run_dir).stage2.evidence_of_key(unit.key)
    if ev.is_file():
        h.update(file_stamp(ev).encode())
    return h.hexdigest()[:16]


def _problem(path: Path, e: Exception) -> tuple[str, str | None]:
    """(detail naming the file and every bad field, the first bad field)."""
    if isinstance(e, ValidationError):  # every problem, not only the first
        fields = [".".join(str(p) for p in err["loc"]) or "<root>" for err in e.errors()]
        return f"{path}: " + "; ".join(f"field {f}: {err['msg']}" for f, err in zip(fields, e.errors())), fields[0]
    return f"{path}: {e}", None


def _key_from_path(root: Path, path: Path) -> str:
    """suite/task/episode_id from a file's place (padded, so every key has three parts)."""
    parts = path.relative_to(root).with_suffix("").parts[-3:]
    return "/".join(("unknown_suite", "unknown_task")[: 3 - len(parts)] + parts)


def _rel(run_dir: Path, path: Path) -> str:
    return path.relative_to(run_dir).as_posix()


def _lengths(run_dir: Path) -> dict[str, float]:
    """Latest valid onset time by key, from the stage-1 manifest (rows that read): the last
    state's time plus one video frame, since a VLM sees a video of total_frames / fps seconds
    (pipeline.labelers.vlm.video_input) and may answer up to its end."""
    manifest = RunLayout(run_dir).stage1.manifest
    if not manifest.is_file():
        return {}
    from pipeline.records import read_episode_rows

    try:
        records, _ = read_episode_rows(manifest)
    except UNREADABLE as e:  # stage 2 reports an unreadable manifest; here it only bounds times
        warn_unreadable(manifest, e, "onset times are bounded by each episode's frames or evidence")
        return {}
    return {r.key: r.steps / r.control_hz + (1 / r.video_fps if r.video_fps else 0.0) for r in records}


def _time_fault(loc: Localization, length: float | None) -> tuple[QuarantineReason, str] | None:
    t = loc.fail_time_s
    if not math.isfinite(t):
        return QuarantineReason.fail_time_not_finite, f"{t} is not a time"
    if t < 0:
        return QuarantineReason.fail_time_negative, f"{t} s is before the episode starts"
    if length is not None and t > length + 1e-6:
        return QuarantineReason.fail_time_beyond_episode, f"{t} s is after the episode's end ({length:g} s)"
    return None


def collect(run_dir: Path) -> list[Unit]:
    """Every stage-2 outcome as a unit, localizations first choice, sorted by key.

    A localization is set aside (a stage-3 QuarantineEntry naming file, field and reason,
    queued as a quarantined item) when its file does not parse, its fail_time_s is not a time
    inside the episode, or its key is claimed by another file too: the file stored under that
    key keeps it, every other claimant is set aside under the key its own path names."""
    s2 = RunLayout(run_dir).stage2
    units: dict[str, Unit] = {}
    loc_root, q_root = s2.localizations_dir, s2.quarantine_dir
    claims: dict[str, list[tuple[Path, Localization]]] = {}

    def set_aside(path: Path, reason: QuarantineReason, detail: str, field: str | None, loc: Localization | None = None) -> None:
        key = _key_from_path(loc_root, path)
        trace = {k: getattr(loc, k) for k in ("model", "prompt_name", "prompt_hash", "raw_text")} if loc else {}
        q = QuarantineEntry(key=key, stage="stage3", source=loc.source if loc else "stage2", reason=reason,
                            detail=detail, file=_rel(run_dir, path), field=field, **trace)
        units.setdefault(key, Unit(key, quarantine=q, source=path, instruction=loc.instruction if loc else None))

    for path in sorted(loc_root.rglob("*.json")) if loc_root.exists() else []:
        try:
            loc = Localization.model_validate_json(path.read_text())
        except (ValidationError, ValueError, OSError) as e:
            set_aside(path, QuarantineReason.unreadable, *_problem(path, e))
            continue
        if loc.key != episode_key(loc.suite, loc.task, loc.episode_id):  # every later step splits the key
            set_aside(path, QuarantineReason.key_mismatch, f"{path}: field key: {loc.key!r} is not "
                      f"suite/task/episode_id ({loc.suite}/{loc.task}/{loc.episode_id})", "key", loc)
            continue
        claims.setdefault(loc.key, []).append((path, loc))
    lengths = _lengths(run_dir)
    for key, claimants in claims.items():
        owners = {p for p, _ in claimants if len(claimants) == 1 or _key_from_path(loc_root, p) == key}
        for path, loc in claimants:
            if path not in owners:
                others = ", ".join(_rel(run_dir, p) for p, _ in claimants if p != path)
                set_aside(path, QuarantineReason.duplicate_key, f"{path}: field key: {key} is also the key of {others}", "key", loc)
                continue
            fault = _time_fault(loc, lengths.get(key) or _duration_of(run_dir, key))
            if fault:
                set_aside(path, fault[0], f"{path}: field fail_time_s: {fault[1]}", "fail_time_s", loc)
            else:
                units[key] = Unit(key, localization=loc, source=path)
    for path in sorted(q_root.rglob("*.json")) if q_root.exists() else []:
        try:
            q = QuarantineEntry.model_validate(json.loads(path.read_text()))
        except (ValidationError, ValueError, OSError) as e:
            key = _key_from_path(q_root, path)
            detail, field = _problem(path, e)
            q = QuarantineEntry(key=key, stage="stage3", source="stage2", reason=QuarantineReason.unreadable, detail=detail,
                                file=_rel(run_dir, path), field=field)
        if not is_key(q.key):
            q = q.model_copy(update={"key": _key_from_path(q_root, path)})
        if q.key not in units:
            units[q.key] = Unit(q.key, quarantine=q, source=path)
    return [units[k] for k in sorted(units)]


def _duration_of(run_dir: Path, key: str) -> float | None:
    """The latest valid onset time from the frame table (last frame + one frame) or the
    evidence (last step), when the manifest has no row; None when neither reads."""
    import pyarrow.parquet as pq

    layout = RunLayout(run_dir)
    frames = layout.stage1.episode_of_key(key).frames
    if frames.is_file():
        try:
            times = sorted(pq.read_table(frames, columns=["time_s"]).column("time_s").to_pylist())
            if times:
                return times[-1] + (times[-1] - times[-2] if len(times) > 1 else 0.0)
        except UNREADABLE as e:  # try the evidence
            warn_unreadable(frames, e, "the episode's length comes from its evidence")
    ev = layout.stage2.evidence_of_key(key)
    return _duration(run_dir, None, layout.rel(ev).as_posix() if ev.is_file() else None)


def _video_fps(path: Path) -> float | None:
    import av

    try:
        with av.open(str(path)) as c:
            rate = c.streams.video[0].average_rate
            return float(rate) if rate else None
    except (*UNREADABLE, av.FFmpegError) as e:  # the page shows the video as missing
        warn_unreadable(path, e, "the review uses the configured video fps")
        return None


def context(run_dir: Path, unit: Unit, control_hz: int, default_fps: float) -> dict:
    """Media paths (relative to the run folder), timing, phases and events of one episode."""
    layout = RunLayout(run_dir)
    files = layout.stage1.episode_of_key(unit.key)
    videos = {cam: layout.rel(files.video(cam)).as_posix() for cam in CAMERAS if files.video(cam).is_file()}
    frames = layout.rel(files.frames).as_posix() if files.frames.is_file() else None
    ev = layout.stage2.evidence_of_key(unit.key)
    evidence = layout.rel(ev).as_posix() if ev.is_file() else None
    fps = _video_fps(run_dir / next(iter(videos.values()))) if videos else None
    duration = _duration(run_dir, frames, evidence)
    loc = unit.localization
    return {
        "videos": videos, "frames": frames, "evidence": evidence, "fps": fps or default_fps,
        "control_hz": control_hz, "duration_s": duration,
        "phases": loc.phases.model_dump(mode="json", exclude={"schema_version"}) if loc else None,
        "events": [e.model_dump(mode="json", exclude={"schema_version"}) for e in loc.events] if loc else [],
        "scene_bddl": loc.scene_bddl if loc else None, "scene_state": loc.scene_state if loc else None,
        "simstate_time_s": loc.simstate_time_s if loc else None,
    }


def _duration(run_dir: Path, frames: str | None, evidence: str | None) -> float | None:
    import pyarrow.parquet as pq

    for rel in (frames, evidence):
        if rel:
            try:
                col = pq.read_table(run_dir / rel, columns=["time_s"]).column("time_s").to_pylist()
                if col:
                    return float(max(col))
            except UNREADABLE as e:
                warn_unreadable(run_dir / rel, e, "the episode's duration comes from the next source, if any")
                continue
    return None
