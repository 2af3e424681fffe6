"""`recover verify DIR`: check a released scenario set, scene by scene.

Input: a release folder (`scenarios.parquet` + `selected_bddl_scenes_<suite>/...`).
Checks per scene (`verify_scene`): files exist and match the manifest's SHA-256; LIBERO's
parser accepts the BDDL; objects of one type share one declaration line; the npy loads and
has the model's state length; the scene restores exactly; the goal does not hold; no object
moves more than `settle_threshold_m` in `settle_check_steps` zero-action steps. Also: the
train/eval split is the one `split.json`'s seed and share draw (`pipeline.release.split`); no
scene file on disk is missing from the manifest, and nothing sits at the top level that a
release does not write (`TOP_LEVEL_FILES`, `TOP_LEVEL_DIRS`).

The scenes are a `Stage` (`VerifyStage`, one unit per scene) run by the `Runner` on the
given executor (`inline` by default; `recover verify --config` uses the config's): scenes
of one task and BDDL share a shard (one environment build), one progress bar. A scene's
report is its done marker's info (`<release>/_build/verify/_done/<scene>.done`), recorded
with everything the report depends on (the manifest row, its files' SHA-256 on disk, the
settle settings, `VERIFY_VERSION`), so a rerun checks only scenes that changed. A scene the
checks themselves fail on (its environment does not build, a worker dies under it) is set
aside with the reason: no marker, reported as a problem, and checked again next time.
Output: a per-scene table and every problem, each naming its file; `main` returns 1 if
there is any problem, else 0. With `--replay` every recovery demo is also replayed in plain
LIBERO (`pipeline.release.replay`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from rich.console import Console
from rich.table import Table

from pipeline.config import ReleaseConfig
from pipeline.layout import (RELEASE_BUILD, RELEASE_CARD, RELEASE_SPLIT, RELEASE_SUMS, SCENE_PREFIX, ReleaseLayout,
                             episode_key, scene_unit)
from pipeline.release.manifest import MANIFEST_NAME, ScenarioRow, read_manifest, sha256_file
from pipeline.release.scene_files import check_bddl, load_state
from pipeline.release.scene_physics import check_goal_unsatisfied, check_restores, check_settled, scene_task
from pipeline.runner import Event, Stage, UnitResult, WorkerContext

if TYPE_CHECKING:
    from pipeline.executors import Executor
    from pipeline.sim import SimEnv, TaskSpec

CHECKS = ("files", "checksum", "bddl", "state", "restore", "goal", "settled")
VERIFY_VERSION = 1  # bump when a check changes, so stored reports are not reused
# what `recover release` writes at the top of a release folder (build.py); anything else is
# stray, e.g. a file dropped in by hand that SHA256SUMS and the manifest would not cover
TOP_LEVEL_FILES = {MANIFEST_NAME, RELEASE_CARD, RELEASE_SUMS, RELEASE_SPLIT}
TOP_LEVEL_DIRS = {RELEASE_BUILD, "figures"}
SCENE_DIR_PREFIX = SCENE_PREFIX


@dataclass
class SceneReport:
    scene: str  # the BDDL path relative to the release folder
    checks: dict[str, bool | None] = field(default_factory=lambda: dict.fromkeys(CHECKS))
    problems: list[str] = field(default_factory=list)

    def record(self, check: str, problems: list[str]) -> bool:
        self.checks[check] = not problems
        self.problems.extend(problems)
        return not problems

    @property
    def ok(self) -> bool:
        return not self.problems

    def info(self) -> dict[str, Any]:
        """What the scene's done marker records."""
        return {"checks": self.checks, "problems": self.problems}

    @classmethod
    def from_info(cls, scene: str, info: dict[str, Any]) -> SceneReport:
        return cls(scene, {c: info["checks"].get(c) for c in CHECKS}, list(info["problems"]))


def check_files(directory: Path, row: ScenarioRow) -> tuple[SceneReport, np.ndarray | None]:
    """The checks without a simulator; the state when the scene is fit for the simulator's."""
    rep = SceneReport(scene=row.bddl_path)
    paths = {rel: directory / rel for rel, _ in row.files()}
    if not rep.record("files", [f"{p}: listed in the manifest but missing" for p in paths.values() if not p.is_file()]):
        return rep, None
    rep.record("checksum", [f"{paths[rel]}: SHA-256 {sha256_file(paths[rel])[:12]}... does not match the manifest's "
                            f"{sha[:12]}..." for rel, sha in row.files() if sha256_file(paths[rel]) != sha])
    problems, _parsed = check_bddl(paths[row.bddl_path])
    bddl_ok = rep.record("bddl", problems)
    problems, state = load_state(paths[row.state_path])
    rep.record("state", problems)
    # a BDDL that breaks the one-line rule parses into a different model (LIBERO keeps only
    # the last line of a type), so its simulator checks would only repeat the problem
    return rep, state if bddl_ok else None


def check_scene_physics(rep: SceneReport, env: SimEnv, directory: Path, row: ScenarioRow, state: np.ndarray,
                        cfg: ReleaseConfig) -> None:
    """Record the simulator's checks of one scene in `rep` (`env` built from its BDDL)."""
    spath = directory / row.state_path
    if state.shape[0] != env.state_dim:
        rep.record("state", [f"{spath}: state has length {state.shape[0]}, but the model of "
                             f"{directory / row.bddl_path} has state_dim {env.state_dim}"])
        return
    if row.state_dim != env.state_dim:
        rep.record("state", [f"{directory / MANIFEST_NAME}: state_dim {row.state_dim} for {spath} "
                             f"differs from the model's {env.state_dim}"])
    if not rep.record("restore", check_restores(env, state, spath)):
        return
    rep.record("goal", check_goal_unsatisfied(env, spath))
    rep.record("settled", check_settled(env, spath, cfg.settle_check_steps, cfg.settle_threshold_m))


def verify_scene(directory: Path, row: ScenarioRow, cfg: ReleaseConfig,
                 env_for: Callable[[TaskSpec], SimEnv]) -> SceneReport:
    """Every check of one scene; `env_for(task)` gives the environment of the scene's model
    (a worker's cached one). An environment that does not build raises (the stage sets the
    scene aside with the reason)."""
    rep, state = check_files(directory, row)
    if state is not None:
        env = env_for(scene_task(row.suite, row.task, row.instruction, directory / row.bddl_path))
        check_scene_physics(rep, env, directory, row, state, cfg)
    return rep


def _unit(row: ScenarioRow) -> str:
    return scene_unit(episode_key(row.suite, row.task, row.episode_id), row.step)


@dataclass
class VerifyStage(Stage[ScenarioRow]):
    """One unit per manifest row; its report is the marker's info (see the module docstring)."""

    directory: Path
    rows: list[ScenarioRow]
    cfg: ReleaseConfig
    name: str = "verify"

    @property
    def root(self) -> Path:
        return ReleaseLayout(self.directory).verify_dir

    def units(self, cfg: Any = None) -> list[ScenarioRow]:
        return sorted(self.rows, key=lambda r: (r.suite, r.task, r.bddl_sha256, _unit(r)))

    def unit_id(self, row: ScenarioRow) -> str:
        return _unit(row)

    def group(self, row: ScenarioRow):
        return row.suite, row.task, row.bddl_sha256  # one model per shard

    def fingerprint(self, row: ScenarioRow) -> dict:
        files = hashlib.sha256()
        for rel, _ in row.files():
            path = self.directory / rel
            files.update(f"{rel}={sha256_file(path) if path.is_file() else 'missing'};".encode())
        # the folder as given too: a report names its files by these paths
        return {"at": str(self.directory), "row": hashlib.sha256(row.model_dump_json().encode()).hexdigest()[:16],
                "files": files.hexdigest()[:16], "verify": VERIFY_VERSION,
                "settle": [self.cfg.settle_check_steps, self.cfg.settle_threshold_m]}

    def process(self, row: ScenarioRow, ctx: WorkerContext) -> UnitResult:
        rep = verify_scene(self.directory, row, self.cfg, ctx.env)
        return UnitResult(info=rep.info(), ok=rep.ok, status="pass" if rep.ok else "fail")

    def set_aside(self, row: ScenarioRow, error: Exception) -> UnitResult:
        return UnitResult.set_aside(type(error).__name__, str(error))


def _not_verified(directory: Path, row: ScenarioRow, ev: Event | None) -> SceneReport:
    why = f"{ev.reason}: {ev.detail}" if ev is not None else "no result"
    return SceneReport(row.bddl_path, problems=[f"{directory / row.bddl_path}: not verified "
                                                f"(set aside: {why})"])


def verify_release(directory: Path, cfg: ReleaseConfig | None = None, executor: Executor | None = None,
                   console: Console | None = None) -> tuple[list[SceneReport], list[str]]:
    """Per-scene reports (in manifest order) and set-level problems (manifest unreadable,
    stray files). The scenes run on `executor` (default: inline, in this process)."""
    from pipeline.executors.local import InlineExecutor
    from pipeline.runner import Runner
    from pipeline.runner.runner import finished

    cfg = cfg or ReleaseConfig()
    directory = Path(directory)
    try:
        rows = read_manifest(directory / MANIFEST_NAME)
    except FileNotFoundError:
        return [], [f"{directory / MANIFEST_NAME}: manifest missing"]
    except ValueError as e:
        return [], [str(e)]
    stage = VerifyStage(directory, rows, cfg)
    aside: dict[str, Event] = {}
    Runner(executor or InlineExecutor(), console=console).run(
        stage, None, on_event=lambda ev: aside.__setitem__(ev.unit, ev) if ev.kind == "set_aside" else None)
    done = finished(stage, rows)
    reports = [SceneReport.from_info(row.bddl_path, done[_unit(row)]) if _unit(row) in done
               else _not_verified(directory, row, aside.get(_unit(row))) for row in rows]
    listed = {rel for row in rows for rel, _ in row.files()}
    stray = sorted(str(p.relative_to(directory)) for d in directory.glob(f"{SCENE_DIR_PREFIX}*")
                   for p in d.rglob("*") if p.is_file())
    set_problems = [f"{directory / rel}: scene file not listed in the manifest" for rel in stray if rel not in listed]
    return reports, set_problems + split_problems(directory, rows) + top_level_problems(directory)


def split_problems(directory: Path, rows: list) -> list[str]:
    """The train/eval split is one side per scene and is what `split.json`'s seed and share
    draw (`pipeline.release.split`); a release built before the split has neither."""
    import json

    from pydantic import ValidationError

    from pipeline.release.split import SplitInfo, check

    path = ReleaseLayout(directory).split
    if not path.is_file():
        with_split = sum(r.split is not None for r in rows)
        return [f"{path}: missing, but {with_split} scene(s) in {directory / MANIFEST_NAME} have a split"] \
            if with_split else []
    try:
        recorded = SplitInfo.model_validate(json.loads(path.read_text()))
    except (ValueError, ValidationError) as e:
        return [f"{path}: not a split record: {e}"]
    return check(rows, recorded, f"{directory / MANIFEST_NAME} / {path.name}")


def top_level_problems(directory: Path) -> list[str]:
    """Every top-level entry of the release that `recover release` does not write."""
    problems = []
    for p in sorted(directory.iterdir()):
        if p.is_dir() and not p.is_symlink() and (p.name in TOP_LEVEL_DIRS or p.name.startswith(SCENE_DIR_PREFIX)):
            continue
        if p.is_file() and not p.is_symlink() and p.name in TOP_LEVEL_FILES:
            continue
        problems.append(f"{p}: not part of a release (stray {'folder' if p.is_dir() else 'file'} at the top level)")
    return problems


def print_report(reports: list[SceneReport], set_problems: list[str], console: Console) -> None:
    table = Table(title=f"scenes ({len(reports)})", show_lines=False)
    table.add_column("scene", overflow="fold")
    for c in CHECKS:
        table.add_column(c, justify="center")
    mark = {True: "[green]ok[/green]", False: "[red]FAIL[/red]", None: "[dim]-[/dim]"}
    for rep in reports:
        table.add_row(rep.scene, *(mark[rep.checks[c]] for c in CHECKS))
    console.print(table)
    problems = [p for r in reports for p in r.problems] + set_problems
    for p in problems:
        console.print(f"[red]problem[/red] {p}", highlight=False, soft_wrap=True)
    bad = sum(not r.ok for r in reports)
    colour = "red" if problems else "green"
    console.print(f"[{colour}]{len(reports) - bad}/{len(reports)} scenes pass; {len(problems)} problem(s)[/{colour}]")


def main(directory: str | Path, cfg: ReleaseConfig | None = None, replay: bool = False,
         demos: str | Path | None = None, *, executor: Executor | None = None) -> int:
    """`replay`: also replay every recovery demo in plain LIBERO (`pipeline.release.replay`;
    `demos`: their folder, default the run's `recoveries/` beside the release)."""
    console = Console()
    reports, set_problems = verify_release(Path(directory), cfg, executor, console)
    print_report(reports, set_problems, console)
    code = 1 if set_problems or any(not r.ok for r in reports) else 0
    if replay:
        from pipeline.release.replay import main_demos

        code |= main_demos(Path(directory), demos, console)
    return code
