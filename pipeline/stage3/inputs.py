"""What stage 3 reads from stages 1 and 2, and the review context built from it.

Inputs (run folder):
  stage2/localizations/<suite>/<task>/<episode_id>.json   records.Localization
  stage2/quarantine/**.json                                records.QuarantineEntry
  stage2/evidence/<suite>/<task>/<episode_id>.parquet      EVIDENCE_SCHEMA
  stage1/episodes/<suite>/<task>/<episode_id>/video_<camera>.mp4, frames.parquet
Outputs: `Unit`s, one per episode key: a localization, or the quarantine entry of an episode
with no localization. A file that does not parse becomes a quarantined unit itself
(reason `unreadable`, naming the file and the field), so nothing is silently dropped.
Paths in the context are relative to the run folder (the server serves nothing else).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from pydantic import ValidationError

from pipeline.records import Localization, QuarantineEntry
from pipeline.sim.render import CAMERAS


@dataclass
class Unit:
    key: str
    localization: Localization | None = None
    quarantine: QuarantineEntry | None = None

    @property
    def unit_id(self) -> str:
        return self.key.replace("/", "__")


def _problem(path: Path, e: Exception) -> str:
    if isinstance(e, ValidationError):  # every problem, not only the first
        return f"{path}: " + "; ".join(
            f"field {'.'.join(str(p) for p in err['loc']) or '<root>'}: {err['msg']}" for err in e.errors())
    return f"{path}: {e}"


def _key_from_path(root: Path, path: Path) -> str:
    rel = path.relative_to(root).with_suffix("")
    return "/".join(rel.parts[-3:]) if len(rel.parts) >= 3 else rel.as_posix()


def collect(run_dir: Path) -> list[Unit]:
    """Every stage-2 outcome as a unit, localizations first choice, sorted by key."""
    s2 = run_dir / "stage2"
    units: dict[str, Unit] = {}
    loc_root, q_root = s2 / "localizations", s2 / "quarantine"
    for path in sorted(loc_root.rglob("*.json")) if loc_root.exists() else []:
        try:
            loc = Localization.model_validate_json(path.read_text())
            units[loc.key] = Unit(loc.key, localization=loc)
        except (ValidationError, ValueError, OSError) as e:
            key = _key_from_path(loc_root, path)
            units.setdefault(key, Unit(key, quarantine=QuarantineEntry(
                key=key, stage="stage3", source="stage2", reason="unreadable", detail=_problem(path, e))))
    for path in sorted(q_root.rglob("*.json")) if q_root.exists() else []:
        try:
            q = QuarantineEntry.model_validate(json.loads(path.read_text()))
        except (ValidationError, ValueError, OSError) as e:
            key = _key_from_path(q_root, path)
            q = QuarantineEntry(key=key, stage="stage3", source="stage2", reason="unreadable", detail=_problem(path, e))
        if q.key not in units:
            units[q.key] = Unit(q.key, quarantine=q)
    return [units[k] for k in sorted(units)]


def _video_fps(path: Path) -> float | None:
    try:
        import av

        with av.open(str(path)) as c:
            rate = c.streams.video[0].average_rate
            return float(rate) if rate else None
    except Exception:  # a broken video is shown as missing by the page, not fatal here
        return None


def context(run_dir: Path, unit: Unit, control_hz: int, default_fps: float) -> dict:
    """Media paths (relative to the run folder), timing, phases and events of one episode."""
    suite, task, ep = unit.key.split("/", 2)
    ep_dir = Path("stage1") / "episodes" / suite / task / ep
    videos = {cam: (ep_dir / f"video_{cam}.mp4").as_posix() for cam in CAMERAS
              if (run_dir / ep_dir / f"video_{cam}.mp4").is_file()}
    frames = (ep_dir / "frames.parquet").as_posix() if (run_dir / ep_dir / "frames.parquet").is_file() else None
    ev = Path("stage2") / "evidence" / suite / task / f"{ep}.parquet"
    evidence = ev.as_posix() if (run_dir / ev).is_file() else None
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
            except Exception:
                continue
    return None
