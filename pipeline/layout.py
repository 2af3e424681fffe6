"""The run folder: every path, id and file name of a run, in one place.

Nothing else in `pipeline/` spells a stage folder or a run file name (tests/test_layout.py
scans the source for it). docs/data-format.md documents every file, one row each with the
call here that gives its path, who writes it, its record and its done marker; the same test
evaluates those calls. Paths only: no IO.

Episode identity has one spelling, built by `episode_key` and taken apart by `parse_key`:
    key           <suite>/<task>/<episode_id>           records, review items, manifests
    unit id       <suite>__<task>__<episode_id>         done markers, flat file names (`unit_id`)
    stage-1 dir   episodes/<suite>/<task>/<episode_id>  relative to stage1/ (`EpisodeRecord.path`)
    scene dir     selected_bddl_scenes_<suite>/<task>/episode_<episode_id>   (`scene_rel`)
    annotation    <suite>/<task>/episode_<episode_id>.json                   (`Stage3Layout.annotation`)
A scene tree (scene dirs under a root) is the same in stage2/, stage3/reviewed_scenes/ and a
release; `scene_files(root, key, step)` names one scene's files in any of them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # records imports this module (episode_key): no import cycle at run time
    from pipeline.config import Config
    from pipeline.records import EpisodeRecord

RESOLVED_CONFIG = "config.resolved.yaml"  # beside each stage's outputs (config.save_resolved)
SUMMARY = "summary.json"
MANIFEST = "episodes.parquet"  # stage 1's manifest, and eval's table of trials
RELEASE_MANIFEST = "scenarios.parquet"
RELEASE_CARD = "README.md"
RELEASE_SUMS = "SHA256SUMS"
RELEASE_SPLIT = "split.json"  # the train/eval split's parameters and counts
RELEASE_BUILD = "_build"  # inside a release folder, outside the released set
QUARANTINE_LOG = "quarantine.jsonl"
REPORT = "report.md"
STATE_SUFFIX = "_sim_state.npy"  # a scene's state file: step_<NNNN>_sim_state.npy
SCENE_PREFIX = "selected_bddl_scenes_"


# ---- episode identity -------------------------------------------------------------------

def episode_key(suite: str, task: str, episode_id: str) -> str:
    """The stable key of an episode: `<suite>/<task>/<episode_id>`."""
    return f"{suite}/{task}/{episode_id}"


def parse_key(key: str) -> tuple[str, str, str]:
    """(suite, task, episode_id) of a key; ValueError naming the key when it has fewer than
    three parts (a slash past the second stays in the episode id: a hand-made stage-2 file
    with one must not stop stage 3, which sets it aside by its path)."""
    parts = key.split("/", 2)
    if len(parts) != 3:
        raise ValueError(f"episode key {key!r} is not <suite>/<task>/<episode_id>")
    return parts[0], parts[1], parts[2]


def is_key(key: str) -> bool:
    """Exactly three parts, as `episode_key` builds them."""
    return key.count("/") == 2


def unit_id(key: str) -> str:
    """Flat, file-safe name of an episode (done markers): `<suite>__<task>__<episode_id>`."""
    return key.replace("/", "__")


def key_of_unit(uid: str) -> str:
    """The key back from a `unit_id`."""
    parts = uid.split("__")
    if len(parts) != 3:
        raise ValueError(f"unit id {uid!r} is not <suite>__<task>__<episode_id>")
    return episode_key(*parts)


# ---- scenes (stage 2, reviewed scenes, a release: the same tree under different roots) ----

def scene_rel(key: str) -> str:
    """A scene folder relative to its tree's root (posix, as written in manifests)."""
    suite, task, ep = parse_key(key)
    return f"{SCENE_PREFIX}{suite}/{task}/episode_{ep}"


def scene_stem(step: int) -> str:
    return f"step_{step:04d}"


@dataclass(frozen=True)
class SceneFiles:
    """One scene: `<dir>/step_<NNNN>.bddl`, `..._sim_state.npy`, `..._history.npz` (+ frames)."""

    dir: Path
    step: int

    @property
    def stem(self) -> str:
        return scene_stem(self.step)

    @property
    def bddl(self) -> Path:
        return self.dir / f"{self.stem}.bddl"

    @property
    def state(self) -> Path:
        return self.dir / f"{self.stem}{STATE_SUFFIX}"

    @property
    def history(self) -> Path:
        return self.dir / f"{self.stem}_history.npz"

    @property
    def history_frames(self) -> Path:
        return self.dir / f"{self.stem}_history_frames.npz"

    @property
    def check_scratch(self) -> Path:
        """Where the normalized BDDL is parsed before the pair is written (removed after)."""
        return self.dir / f".{self.stem}.check.bddl"


SCENE_GLOB = f"{SCENE_PREFIX}*/*/episode_*/step_*.bddl"  # every scene's BDDL under a tree's root
_SCENE_RE = re.compile(rf"{SCENE_PREFIX}(?P<suite>[^/]+)/(?P<task>[^/]+)/episode_(?P<ep>[^/]+)/step_(?P<step>\d+)\.bddl$")


def parse_scene_bddl(rel: str) -> tuple[str, int] | None:
    """(episode key, step) of a scene BDDL path (relative to its tree's root), None if the
    name does not follow the layout."""
    m = _SCENE_RE.search(rel)
    return (episode_key(m["suite"], m["task"], m["ep"]), int(m["step"])) if m else None


def scene_id(key: str, step: int) -> str:
    """A scene's id in evaluations: `<key>/step_<NNNN>`."""
    return f"{key}/{scene_stem(step)}"


def scene_unit(key: str, step: int) -> str:
    """A scene's id as one file name (its done markers): `scene_id` with `/` as `__`."""
    return scene_id(key, step).replace("/", "__")


def scene_dir(root: Path, key: str) -> Path:
    return Path(root) / scene_rel(key)


def scene_files(root: Path, key: str, step: int) -> SceneFiles:
    return SceneFiles(scene_dir(root, key), step)


# ---- stage 1 ------------------------------------------------------------------------------

def video_name(camera: str) -> str:
    return f"video_{camera}.mp4"


@dataclass(frozen=True)
class EpisodeFiles:
    """A stage-1 episode folder and its files."""

    dir: Path

    @property
    def states(self) -> Path:
        return self.dir / "states.npy"

    @property
    def actions(self) -> Path:
        """(steps, 7) float64: the actions exactly as stepped (steps.parquet rounds them)."""
        return self.dir / "actions.npy"

    @property
    def steps(self) -> Path:
        return self.dir / "steps.parquet"

    @property
    def frames(self) -> Path:
        return self.dir / "frames.parquet"

    @property
    def truth(self) -> Path:
        return self.dir / "truth.parquet"

    def video(self, camera: str) -> Path:
        return self.dir / video_name(camera)


@dataclass(frozen=True)
class Stage1Layout:
    root: Path

    @property
    def manifest(self) -> Path:
        return self.root / MANIFEST

    @property
    def summary(self) -> Path:
        return self.root / SUMMARY

    @property
    def rerender(self) -> Path:
        """The root of `recover stage1 --rerender` (its runner's done markers)."""
        return self.root / "_rerender"

    @staticmethod
    def episode_rel(key: str) -> str:
        """An episode folder relative to stage1/ (`EpisodeRecord.path`)."""
        return f"episodes/{episode_key(*parse_key(key))}"

    def episode_dir(self, key: str) -> Path:
        return self.root / self.episode_rel(key)

    def episode(self, rec: EpisodeRecord) -> EpisodeFiles:
        """The folder a manifest row names (`rec.path`)."""
        return EpisodeFiles(self.root / rec.path)

    def episode_of_key(self, key: str) -> EpisodeFiles:
        return EpisodeFiles(self.episode_dir(key))

    def video(self, rec: EpisodeRecord, camera: str) -> Path | None:
        """The camera's video as the manifest row lists it (`rec.videos`), None if not rendered."""
        return self.video_in(self.root / rec.path, rec, camera)

    @staticmethod
    def video_in(folder: Path, rec: EpisodeRecord, camera: str) -> Path | None:
        name = rec.videos.get(camera)
        return Path(folder) / name if name else None

    @property
    def errors_dir(self) -> Path:
        """`<unit>.txt` per episode that failed last time (removed once it finishes)."""
        return self.root / "errors"

    def error(self, uid: str) -> Path:
        return self.errors_dir / f"{uid}.txt"


# ---- stage 2 ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Stage2Layout:
    """Per-episode files as paths relative to the root (they are recorded in Localizations)."""

    root: Path  # <run>/stage2

    def _rel(self, kind: str, rec: EpisodeRecord, suffix: str) -> Path:
        return Path(kind) / rec.suite / rec.task / f"{rec.episode_id}{suffix}"

    def evidence(self, rec: EpisodeRecord) -> Path:
        return self._rel("evidence", rec, ".parquet")

    def localization(self, rec: EpisodeRecord) -> Path:
        return self._rel("localizations", rec, ".json")

    def quarantine(self, rec: EpisodeRecord) -> Path:
        return self._rel("quarantine", rec, ".json")

    def quarantine_for_key(self, key: str) -> Path:
        """A manifest row with no usable record still has a key (see records.read_episode_rows)."""
        return Path("quarantine") / f"{key}.json"

    def vlm(self, rec: EpisodeRecord) -> Path:
        return self._rel("vlm", rec, ".json")

    @property
    def vlm_dir(self) -> Path:
        """The VLM step's answers, and its done markers (`_done/`)."""
        return self.root / "vlm"

    def abs(self, rel: Path) -> Path:
        return self.root / rel

    def localization_of_key(self, key: str) -> Path:
        suite, task, ep = parse_key(key)
        return self.root / "localizations" / suite / task / f"{ep}.json"

    def evidence_of_key(self, key: str) -> Path:
        suite, task, ep = parse_key(key)
        return self.root / "evidence" / suite / task / f"{ep}.parquet"

    @property
    def localizations_dir(self) -> Path:
        return self.root / "localizations"

    @property
    def quarantine_dir(self) -> Path:
        return self.root / "quarantine"

    @property
    def localizations_table(self) -> Path:
        return self.root / "localizations.parquet"

    @property
    def agreement(self) -> Path:
        return self.root / "agreement.json"

    @property
    def agreement_figure(self) -> Path:
        return self.root / "agreement.png"

    @property
    def summary(self) -> Path:
        return self.root / SUMMARY

    def scene_dir(self, key: str) -> Path:
        return scene_dir(self.root, key)

    def scene(self, key: str, step: int) -> SceneFiles:
        return scene_files(self.root, key, step)


# ---- stage 3 ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Stage3Layout:
    root: Path  # <run>/stage3

    def _per_key(self, kind: str, key: str) -> Path:
        suite, task, ep = parse_key(key)
        return self.root / kind / suite / task / f"{ep}.json"

    def characterization(self, key: str) -> Path:
        return self._per_key("characterizations", key)

    def quarantine(self, key: str) -> Path:
        return self._per_key("quarantine", key)

    @property
    def review_db(self) -> Path:
        return self.root / "review.sqlite"

    @property
    def review_status(self) -> Path:
        return self.root / "review_status.json"

    @property
    def review_confusion(self) -> Path:
        return self.root / "review_confusion.png"

    @property
    def annotations(self) -> Path:
        """Default export folder of final reviewed annotations."""
        return self.root / "annotations"

    @staticmethod
    def annotation(root: Path, suite: str, task: str, episode_id: str) -> Path:
        """One exported annotation under an export folder `root`."""
        return Path(root) / suite / task / f"episode_{episode_id}.json"

    ANNOTATION_GLOB = "*/*/episode_*.json"
    ANNOTATIONS_TABLE = "annotations.parquet"
    MODEL_VS_TRUTH = "model_vs_truth.json"  # the export's model and final records vs the generator's truth

    @property
    def reviewed_scenes(self) -> Path:
        """Root of the scene tree re-snapshotted at reviewed onsets (release.resnapshot)."""
        return self.root / "reviewed_scenes"

    @property
    def summary(self) -> Path:
        return self.root / SUMMARY


# ---- release, eval, bench ---------------------------------------------------------------

@dataclass(frozen=True)
class ReleaseLayout:
    root: Path

    @property
    def manifest(self) -> Path:
        return self.root / RELEASE_MANIFEST

    @property
    def card(self) -> Path:
        return self.root / RELEASE_CARD

    @property
    def sums(self) -> Path:
        return self.root / RELEASE_SUMS

    @property
    def split(self) -> Path:
        return self.root / RELEASE_SPLIT

    @property
    def build_dir(self) -> Path:
        """Not part of the set: build time, quarantined annotations, cache."""
        return self.root / RELEASE_BUILD

    @property
    def quarantine_log(self) -> Path:
        return self.build_dir / QUARANTINE_LOG

    @property
    def verify_dir(self) -> Path:
        """`recover verify`'s done markers, one per checked scene (`_done/`)."""
        return self.build_dir / "verify"

    @staticmethod
    def scene_base(key: str, step: int) -> str:
        """Release-relative stem of a scene's files: `<scene_rel>/step_<NNNN>`."""
        return f"{scene_rel(key)}/{scene_stem(step)}"


@dataclass(frozen=True)
class EvalLayout:
    root: Path  # <run>/eval

    def trial(self, uid: str) -> Path:
        return self.root / "trials" / f"{uid}.parquet"

    def quarantine(self, uid: str) -> Path:
        return self.quarantine_dir / f"{uid}.json"

    @property
    def quarantine_dir(self) -> Path:
        return self.root / "quarantine"

    @property
    def episodes(self) -> Path:
        return self.root / MANIFEST

    @property
    def metrics(self) -> Path:
        return self.root / "metrics.json"

    @property
    def report(self) -> Path:
        return self.root / REPORT

    @property
    def quarantine_log(self) -> Path:
        return self.root / QUARANTINE_LOG


@dataclass(frozen=True)
class RecoveriesLayout:
    """Recovery demonstrations (`recover demos`): training data, outside the checksummed release."""

    root: Path  # <run>/recoveries

    DEMOS = "demos.parquet"
    SCENES = "scenes.jsonl"

    @property
    def demos(self) -> Path:
        return self.root / self.DEMOS

    @property
    def scenes_log(self) -> Path:
        return self.root / self.SCENES

    def scene_dir(self, key: str, step: int) -> Path:
        """The demos of one released scene (`demo_<k>/` inside, stage-1 episode files each)."""
        return self.root / Stage1Layout.episode_rel(key) / scene_stem(step)

    def error(self, unit: str) -> Path:
        return self.root / "errors" / f"{unit}.txt"


@dataclass(frozen=True)
class RunLayout:
    """A run folder. `release_root` is `release.output_dir` when the config sets one."""

    root: Path
    release_root: Path | None = None

    @classmethod
    def of(cls, cfg: Config) -> RunLayout:
        return cls(Path(cfg.out), Path(cfg.release.output_dir) if cfg.release.output_dir else None)

    @property
    def stage1(self) -> Stage1Layout:
        return Stage1Layout(self.root / "stage1")

    @property
    def stage2(self) -> Stage2Layout:
        return Stage2Layout(self.root / "stage2")

    @property
    def stage3(self) -> Stage3Layout:
        return Stage3Layout(self.root / "stage3")

    @property
    def release(self) -> ReleaseLayout:
        return ReleaseLayout(self.release_root if self.release_root else self.root / "release")

    @property
    def eval(self) -> EvalLayout:
        return EvalLayout(self.root / "eval")

    def rel(self, path: Path) -> Path:
        """A path inside the run, relative to the run folder (as review items record them)."""
        return Path(path).relative_to(self.root)

    def bench(self, localizer: str) -> Path:
        return self.root / "bench" / f"localize_{localizer}"

    @property
    def recoveries(self) -> RecoveriesLayout:
        return RecoveriesLayout(self.root / "recoveries")

    @property
    def lerobot(self) -> Path:
        return self.root / "lerobot"

    @property
    def pipeline(self) -> Path:
        """`recover run`'s own folder: `_done/<step>.done` of its whole-run steps (pipeline/flow.py)."""
        return self.root / "pipeline"
