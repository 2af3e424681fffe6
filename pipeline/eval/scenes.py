"""Find the recovery scenes to evaluate.

Inputs, either of:
- a released scenario set: `scenarios.parquet` (`pipeline.release.manifest`) lists every
  scene with its files (relative paths), level, category and source episode;
- stage 2 output (`<run>/stage2/`) or any folder laid out like a release without a
  manifest: `selected_bddl_scenes_<suite>/<task>/episode_<id>/step_<NNNN>.bddl` beside
  `step_<NNNN>_sim_state.npy`; level and category are then unknown (None, reported as
  "unlabeled").
Output: `Scene`s sorted by (suite, task, episode, step), and a list of problems (a .bddl
without its state, an unparsable name), each naming the file: those scenes are skipped.

Invariant: `scene_id` = `<suite>/<task>/<episode_id>/step_<NNNN>` is stable across copies
of a set, so it can seed per-scene randomness and key results.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from pipeline.layout import SCENE_GLOB, STATE_SUFFIX, ReleaseLayout, episode_key, parse_key, parse_scene_bddl, scene_id
from pipeline.sim import TaskSpec, get_task


@dataclass(frozen=True)
class Scene:
    suite: str
    task: str
    episode_id: str
    step: int  # failure-onset step of the source episode (the scene's state)
    bddl_path: Path
    state_path: Path
    level: str | None = None
    category: str | None = None
    instruction: str | None = None
    init_state: int | None = None  # official init state the source episode started from
    history_paths: tuple[Path, ...] = field(default_factory=tuple)
    split: str | None = None  # train | eval in a release with a split; None: no split
    fail_step: int | None = None  # the (reviewed) failure onset of a released scene; None: unknown

    @property
    def scene_id(self) -> str:
        return scene_id(self.source_key, self.step)

    @property
    def source_key(self) -> str:
        """The stage-1 episode key of the rollout this scene was cut from."""
        return episode_key(self.suite, self.task, self.episode_id)


def _from_manifest(root: Path, manifest: Path) -> tuple[list[Scene], list[str]]:
    from pipeline.release.manifest import read_manifest

    scenes, problems = [], []
    for r in read_manifest(manifest):
        bddl, state = root / r.bddl_path, root / r.state_path
        missing = [str(p) for p in (bddl, state) if not p.is_file()]
        if missing:
            problems.append(f"{manifest}: scene {r.suite}/{r.task}/{r.episode_id} step {r.step}: missing {missing}")
            continue
        scenes.append(Scene(r.suite, r.task, r.episode_id, r.step, bddl, state, r.level, r.category,
                            r.instruction, r.init_state, tuple(root / h for h in r.history_paths),
                            None if r.split is None else str(r.split), r.fail_step))
    return scenes, problems


def _from_layout(root: Path) -> tuple[list[Scene], list[str]]:
    scenes, problems = [], []
    for bddl in sorted(root.glob(SCENE_GLOB)):
        parsed = parse_scene_bddl(bddl.relative_to(root).as_posix())
        if parsed is None:
            problems.append(f"{bddl}: name does not follow step_<NNNN>.bddl")
            continue
        state = bddl.with_name(bddl.stem + STATE_SUFFIX)
        if not state.is_file():
            problems.append(f"{bddl}: no state file {state.name} beside it")
            continue
        history = tuple(sorted(p for p in bddl.parent.glob(f"{bddl.stem}_history*") if p.is_file()))
        (suite, task, ep), step = parse_key(parsed[0]), parsed[1]
        scenes.append(Scene(suite, task, ep, step, bddl, state, history_paths=history))
    return scenes, problems


def find_scenes(root: str | Path) -> tuple[list[Scene], list[str]]:
    """Scenes under `root` (a release with a manifest, or stage-2 style layout)."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such scene folder")
    manifest = ReleaseLayout(root).manifest
    scenes, problems = _from_manifest(root, manifest) if manifest.is_file() else _from_layout(root)
    scenes.sort(key=lambda s: (s.suite, s.task, s.episode_id, s.step))
    return scenes, problems


def choose_split(scenes: list[Scene], which: str) -> tuple[list[Scene], str]:
    """The scenes of one side of the release's train/eval split (`eval.split`: eval, train or
    all) and a sentence for the report saying which were evaluated."""
    if which not in ("eval", "train", "all"):
        raise ValueError(f"eval.split must be eval, train or all, got {which!r}")
    if not any(s.split is not None for s in scenes):
        return scenes, f"all {len(scenes)} scenes (the scene folder has no train/eval split)"
    if which == "all":
        n_train = sum(s.split == "train" for s in scenes)
        return scenes, (f"all {len(scenes)} scenes, train ({n_train}) and eval ({len(scenes) - n_train}) alike: "
                        f"scores on train scenes are not held out")
    chosen = [s for s in scenes if s.split == which]
    note = f"the {which} split: {len(chosen)} of {len(scenes)} scenes"
    return chosen, note + (" (the scenes recovery demonstrations were recorded on: not held out)"
                           if which == "train" else " (held out from the recovery demonstrations)")


def scene_task(scene: Scene) -> TaskSpec:
    """The registry task of a scene, with the scene's own BDDL file in place of LIBERO's.

    A released scene is self-contained: its (normalized) BDDL is what the state vector was
    saved against. `pipeline.sim.EnvCache` keys environments by BDDL content, so scenes of
    one task share one environment per worker.
    """
    base = get_task(scene.suite, scene.task)
    return base.model_copy(update={"bddl_path": scene.bddl_path})
