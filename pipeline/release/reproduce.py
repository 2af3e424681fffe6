"""`recover reproduce`: rebuild the scenario set from scratch and compare it with the stored one.

Inputs: the config of a run that has a release (`<release>/scenarios.parquet`) and the final
reviewed annotations (`<run>/stage3/annotations/`). Reviewed labels are inputs, not
something to regenerate: stages 1 and 2 are re-run into a fresh folder
(`<run>.reproduce/`, emptied first), the stored annotations are copied in, and the release
is rebuilt there. Output: a per-file comparison (same / differs / missing / extra) of every
released file, by the SHA-256 in the two manifests and SHA256SUMS; `run` returns 0 when
everything is identical, else 1.
"""

from __future__ import annotations

import importlib
import shutil
from pathlib import Path

from rich.console import Console
from rich.table import Table

from pipeline.config import Config
from pipeline.errors import FatalError
from pipeline.layout import RunLayout
from pipeline.release.build import SUMS_NAME, build, release_dir
from pipeline.release.manifest import MANIFEST_NAME, read_manifest


def file_sums(release: Path) -> dict[str, str]:
    """relative path -> SHA-256 of every released file (manifest rows and SHA256SUMS)."""
    sums = {}
    if (release / SUMS_NAME).is_file():
        for line in (release / SUMS_NAME).read_text().splitlines():
            sha, rel = line.split("  ", 1)
            sums[rel] = sha
    for row in read_manifest(release / MANIFEST_NAME):
        sums.update(dict(row.files()))
    return sums


def compare(stored: Path, rebuilt: Path) -> list[tuple[str, str]]:
    """(relative path, status) for every file that is not byte-identical."""
    a, b = file_sums(stored), file_sums(rebuilt)
    out = []
    for rel in sorted(a.keys() | b.keys()):
        if rel not in b:
            out.append((rel, "missing in rebuild"))
        elif rel not in a:
            out.append((rel, "extra in rebuild"))
        elif a[rel] != b[rel]:
            out.append((rel, f"differs ({a[rel][:12]} -> {b[rel][:12]})"))
    return out


def fresh_config(cfg: Config) -> Config:
    fresh = cfg.out.parent / f"{cfg.out.name}.reproduce"
    return cfg.model_copy(update={
        "run": cfg.run.model_copy(update={"output_dir": fresh}),
        "release": cfg.release.model_copy(update={"output_dir": None}),
    })


def _rerun(cfg: Config, new: Config) -> None:
    """Stages 1-2 of `cfg` again into `new`'s fresh folder, with `cfg`'s stored annotations."""
    annotations = RunLayout.of(cfg).stage3.annotations
    if not annotations.is_dir():
        raise FatalError(f"{annotations}: no final reviewed annotations to reproduce from")
    if new.out.exists():
        shutil.rmtree(new.out)
    for stage in ("pipeline.stage1.run:run", "pipeline.stage2.run:run"):
        module, func = stage.split(":")
        getattr(importlib.import_module(module), func)(new)
    shutil.copytree(annotations, RunLayout.of(new).stage3.annotations)


def rebuild(cfg: Config) -> Config:
    """Re-run stages 1-2 into the fresh folder, copy the stored annotations, release there.
    A merged release (`release.merge_runs`) re-runs each merged run too, from its own
    resolved config (`<run>/config.resolved.yaml`), into `<run>.reproduce/`, and merges those."""
    from pipeline.config import ConfigError, load_config
    from pipeline.layout import RESOLVED_CONFIG

    merged = []
    for run in cfg.release.merge_runs:
        try:
            other = load_config(Path(run) / RESOLVED_CONFIG)
        except ConfigError as e:
            raise FatalError(f"release.merge_runs: cannot reproduce {run}: {e}") from None
        other_new = fresh_config(other)
        _rerun(other, other_new)
        merged.append(other_new.out)
    new = fresh_config(cfg)
    new = new.model_copy(update={"release": new.release.model_copy(update={"merge_runs": merged})})
    _rerun(cfg, new)
    build(new)
    return new


def run(cfg: Config) -> int:
    console = Console()
    stored = release_dir(cfg)
    if not (stored / MANIFEST_NAME).is_file():
        raise FatalError(f"{stored / MANIFEST_NAME}: no stored release to compare with; run `recover release` first")
    new = rebuild(cfg)
    diffs = compare(stored, release_dir(new))
    total = len(file_sums(stored))
    if not diffs:
        console.print(f"[green]reproduced: all {total} released files are byte-identical[/green] ({release_dir(new)})")
        return 0
    table = Table(title=f"{len(diffs)} of {total} files differ")
    table.add_column("file", overflow="fold")
    table.add_column("status")
    for rel, status in diffs:
        table.add_row(rel, status)
    console.print(table)
    return 1
