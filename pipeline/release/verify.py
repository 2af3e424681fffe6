"""`recover verify DIR`: check a released scenario set, scene by scene.

Input: a release folder (`scenarios.parquet` + `selected_bddl_scenes_<suite>/...`).
Checks per scene: files exist and match the manifest's SHA-256; LIBERO's parser accepts the
BDDL; objects of one type share one declaration line; the npy loads and has the model's
state length; the scene restores exactly; the goal does not hold; no object moves more than
`settle_threshold_m` in `settle_check_steps` zero-action steps. Also: the train/eval split is
the one `split.json`'s seed and share draw (`pipeline.release.split`); no scene file on disk
is missing from the manifest, and nothing sits at the top level that a release does not
write (`TOP_LEVEL_FILES`, `TOP_LEVEL_DIRS`). Scenes are grouped by task (and BDDL model signature), so each
environment is built once. Output: a per-scene table and every problem, each naming its file;
`main` returns 1 if there is any problem, else 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import groupby
from pathlib import Path

from rich.console import Console
from rich.progress import track
from rich.table import Table

from pipeline.config import ReleaseConfig
from pipeline.layout import RELEASE_BUILD, RELEASE_CARD, RELEASE_SPLIT, RELEASE_SUMS, SCENE_PREFIX, ReleaseLayout
from pipeline.release.manifest import MANIFEST_NAME, read_manifest, sha256_file
from pipeline.release.scene_files import check_bddl, load_state
from pipeline.release.scene_physics import check_goal_unsatisfied, check_restores, check_settled, scene_task
from pipeline.sim import SimEnv

CHECKS = ("files", "checksum", "bddl", "state", "restore", "goal", "settled")
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


def _signature(parsed: dict) -> tuple:
    # what the compiled model depends on: the declared objects, fixtures and regions
    return tuple(sorted(parsed.get("objects", {}).items())), tuple(sorted(parsed.get("fixtures", {}).items())), \
        tuple(sorted(parsed.get("regions", {})))


def verify_release(directory: Path, cfg: ReleaseConfig | None = None) -> tuple[list[SceneReport], list[str]]:
    """Per-scene reports and set-level problems (manifest unreadable, stray files)."""
    cfg = cfg or ReleaseConfig()
    directory = Path(directory)
    try:
        rows = read_manifest(directory / MANIFEST_NAME)
    except FileNotFoundError:
        return [], [f"{directory / MANIFEST_NAME}: manifest missing"]
    except ValueError as e:
        return [], [str(e)]
    reports, pending = [], []  # pending: scenes that passed the file checks, for the simulator
    for row in rows:
        rep = SceneReport(scene=row.bddl_path)
        reports.append(rep)
        paths = {rel: directory / rel for rel, _ in row.files()}
        if not rep.record("files", [f"{p}: listed in the manifest but missing" for p in paths.values() if not p.is_file()]):
            continue
        rep.record("checksum", [f"{paths[rel]}: SHA-256 {sha256_file(paths[rel])[:12]}... does not match the manifest's "
                                f"{sha[:12]}..." for rel, sha in row.files() if sha256_file(paths[rel]) != sha])
        problems, parsed = check_bddl(paths[row.bddl_path])
        bddl_ok = rep.record("bddl", problems)
        problems, state = load_state(paths[row.state_path])
        rep.record("state", problems)
        # a BDDL that breaks the one-line rule parses into a different model (LIBERO keeps only
        # the last line of a type), so its simulator checks would only repeat the problem
        if bddl_ok and state is not None:
            pending.append((row, rep, parsed, state))

    pending.sort(key=lambda x: (x[0].suite, x[0].task, _signature(x[2])))
    for _, group in groupby(pending, key=lambda x: (x[0].suite, x[0].task, _signature(x[2]))):
        group = list(group)
        first = group[0]
        try:  # one build per task and model; its BDDL may differ from LIBERO's, so no shared cache
            env = SimEnv(scene_task(first[0].suite, first[0].task, first[0].instruction, directory / first[0].bddl_path))
        except Exception as e:
            for row, rep, _, _ in group:
                rep.record("restore", [f"{directory / row.bddl_path}: environment does not build: {type(e).__name__}: {e}"])
            continue
        with env:
            for row, rep, _parsed, state in track(group, description=f"checking {first[0].task[:40]}", transient=True):
                spath = directory / row.state_path
                if state.shape[0] != env.state_dim:
                    rep.record("state", [f"{spath}: state has length {state.shape[0]}, but the model of "
                                         f"{directory / row.bddl_path} has state_dim {env.state_dim}"])
                    continue
                if row.state_dim != env.state_dim:
                    rep.record("state", [f"{directory / MANIFEST_NAME}: state_dim {row.state_dim} for {spath} "
                                         f"differs from the model's {env.state_dim}"])
                if not rep.record("restore", check_restores(env, state, spath)):
                    continue
                rep.record("goal", check_goal_unsatisfied(env, spath))
                rep.record("settled", check_settled(env, spath, cfg.settle_check_steps, cfg.settle_threshold_m))

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


def main(directory: str | Path, cfg: ReleaseConfig | None = None) -> int:
    console = Console()
    reports, set_problems = verify_release(Path(directory), cfg)
    print_report(reports, set_problems, console)
    return 1 if set_problems or any(not r.ok for r in reports) else 0
