"""The train/eval split of a release: which scenes get recovery demonstrations.

Inputs: the manifest rows and `release.split` (`train_share`, `seed`). Output: each row's
`split` (`train` / `eval`) and `SplitInfo`, written as the release's `split.json`.

Rule (one implementation, used by `recover release` and re-run by `recover verify`): a
scene's score is u = SHA-256("split/<seed>/<scene id>") read as a number in [0, 1); it is
`train` when u < train_share. The side of a scene depends only on its own id and the seed,
so the same release and seed give the same split, and a release that adds scenes (more
episodes, another generator) leaves every existing scene on its side. Sampling is uniform
within each suite x level stratum (the expected train share is `train_share` in each), as
the reference samples its recovery scenes uniformly over the suites. Two corrections keep
both sides covering the release when it is small: a suite of >= 2 scenes that drew no train
scene gets its lowest-scored scene as train (unless train_share is 0), and a suite x level of
>= 2 scenes that drew no eval scene gives its highest-scored scene to eval. Only these
corrections can move an existing scene when scenes are added (back to its drawn side, once
its suite or stratum draws one of each side by itself).
"""

from __future__ import annotations

import hashlib
from collections import Counter, defaultdict
from collections.abc import Sequence

from pydantic import BaseModel, ConfigDict

from pipeline.config import SplitConfig
from pipeline.layout import episode_key, scene_id
from pipeline.release.manifest import ScenarioRow
from pipeline.vocab import Split

METHOD = "sha256-threshold/suite-level/v2"


class SplitInfo(BaseModel):
    """`split.json`: how the split was drawn (enough to redraw it) and its counts."""

    model_config = ConfigDict(extra="forbid")

    method: str = METHOD
    seed: int
    train_share: float
    strata: str = "suite x level"
    counts: dict[str, int]  # "<split>/<suite>/<level>" -> scenes


def row_scene_id(row: ScenarioRow) -> str:
    return scene_id(episode_key(row.suite, row.task, row.episode_id), row.step)


def score(seed: int, sid: str) -> float:
    digest = hashlib.sha256(f"split/{seed}/{sid}".encode()).digest()
    return int.from_bytes(digest[:8], "big") / 2**64


def assign(rows: Sequence[ScenarioRow], cfg: SplitConfig) -> list[Split]:
    """The side of each row, in the rows' order."""
    scores = [score(cfg.seed, row_scene_id(r)) for r in rows]
    sides = [Split.train if u < cfg.train_share else Split.eval for u in scores]
    suites: dict[str, list[int]] = defaultdict(list)
    strata: dict[tuple[str, str], list[int]] = defaultdict(list)
    for i, r in enumerate(rows):
        suites[r.suite].append(i)
        strata[(r.suite, str(r.level))].append(i)
    if cfg.train_share > 0:  # every suite gets demonstrations
        for idx in suites.values():
            if len(idx) >= 2 and not any(sides[i] is Split.train for i in idx):
                sides[min(idx, key=lambda i: scores[i])] = Split.train
    for idx in strata.values():  # every suite x level stays in the evaluation
        if len(idx) >= 2 and all(sides[i] is Split.train for i in idx):
            sides[max(idx, key=lambda i: scores[i])] = Split.eval
    return sides


def apply(rows: Sequence[ScenarioRow], cfg: SplitConfig) -> tuple[list[ScenarioRow], SplitInfo]:
    sides = assign(rows, cfg)
    out = [r.model_copy(update={"split": s}) for r, s in zip(rows, sides, strict=True)]
    return out, info(out, cfg)


def info(rows: Sequence[ScenarioRow], cfg: SplitConfig) -> SplitInfo:
    counts = Counter(f"{r.split}/{r.suite}/{r.level}" for r in rows)
    return SplitInfo(seed=cfg.seed, train_share=cfg.train_share, counts=dict(sorted(counts.items())))


def check(rows: Sequence[ScenarioRow], recorded: SplitInfo, where: str) -> list[str]:
    """Problems of a release's split: a row without a side, a side the seed does not give,
    counts that differ from `split.json` (`where` names the files)."""
    if recorded.method != METHOD:
        return [f"{where}: split method {recorded.method!r} is not this version's {METHOD!r}"]
    problems = [f"{where}: scene {row_scene_id(r)} has no split" for r in rows if r.split is None]
    problems += [f"{where}: scene {sid} is listed {n} times" for sid, n in
                 sorted(Counter(row_scene_id(r) for r in rows).items()) if n > 1]
    if problems:
        return problems
    cfg = SplitConfig(seed=recorded.seed, train_share=recorded.train_share)
    for r, side in zip(rows, assign(rows, cfg), strict=True):
        if r.split != side:
            problems.append(f"{where}: scene {row_scene_id(r)} is {r.split}, but seed {recorded.seed} and "
                            f"train_share {recorded.train_share} put it in {side}")
    if info(rows, cfg).counts != recorded.counts:
        problems.append(f"{where}: split.json's counts differ from the manifest's split column")
    return problems
