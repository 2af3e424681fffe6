"""Recovery metrics, as pure functions of evaluation rows (`records.MetricRow`, e.g. from
`records.read_rows`). Nothing here touches the simulator.

Definitions (the reference's, with the choices the issue left open made explicit):
- RSR (recovery success rate) of a subset = successes / trials over the `scene`-mode rows
  matching the filters (any of: policy, chunk_size, suite, level, gripper, task, ...).
  The RSR of an empty subset is undefined: NaN (reports print it as "—"), never 0, so a
  missing cell is not mistaken for a policy that always fails.
- LIBERO success of a subset = successes / trials over the `official`-mode rows: the policy
  from LIBERO's official init states, the benchmark's standard success rate, drawn beside
  RSR (NaN when none).
- R_k = the RSR of task k (its scenes' trials pooled).
- RC (recovery consistency) = 1 - std_k(R_k), with the *population* std (ddof = 0): the
  tasks evaluated are the whole population being described, not a sample of some larger
  set, and a single task then has RC = 1 rather than an undefined sample std. RC of a
  subset with no task is NaN.
- RD (recovery degradation) = 1 - (M_post + eps) / (M_pre + eps), where M_pre / M_during /
  M_post are the success rates of the `rd`-mode reruns started before the failure onset,
  while it unfolds and after it (stage 2's phases; `eval.rd`). Matched subsets: only scenes
  (source episodes) with at least one pre *and* one post rerun count, all three rates pool
  the reruns of exactly those scenes (M_during is NaN when they have no during rerun: a
  phase shorter than `rd_every_steps`). No such scene: NaN.
  RD > 0: the policy does worse after the failure than before it; 0: no degradation;
  < 0: it does better (e.g. the failure happened to help). eps keeps 0/0 finite (RD = 0).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass

from pipeline.eval.records import MetricRow

NAN = float("nan")


def _value(v):
    return getattr(v, "value", v)  # str enums compare by value


def select(rows: Iterable[MetricRow], **where) -> list[MetricRow]:
    """Rows whose columns equal every given value (a list/tuple/set value means "any of")."""
    unknown = set(where) - set(MetricRow.model_fields)
    if unknown:
        raise ValueError(f"no metric column {sorted(unknown)}; columns: {list(MetricRow.model_fields)}")
    out = []
    for r in rows:
        ok = True
        for k, want in where.items():
            have = _value(getattr(r, k))
            if isinstance(want, (list, tuple, set, frozenset)):
                ok = have in {_value(w) for w in want}
            else:
                ok = have == _value(want)
            if not ok:
                break
        if ok:
            out.append(r)
    return out


def success_rate(rows: Iterable[MetricRow]) -> float:
    rows = list(rows)
    if not rows:
        return NAN
    return sum(r.success for r in rows) / len(rows)


def libero_success(rows: Iterable[MetricRow], **where) -> float:
    """Standard LIBERO success over the official-init-state trials matching `where`."""
    return success_rate(select(rows, mode="official", **where))


def rsr(rows: Iterable[MetricRow], **where) -> float:
    """Recovery success rate over the scene trials matching `where`; NaN when none match."""
    return success_rate(select(rows, mode="scene", **where))


def task_rates(rows: Iterable[MetricRow], **where) -> dict[tuple[str, str], float]:
    """R_k: (suite, task) -> RSR of that task's scene trials matching `where`."""
    by_task: dict[tuple[str, str], list[MetricRow]] = defaultdict(list)
    for r in select(rows, mode="scene", **where):
        by_task[(r.suite, r.task)].append(r)
    return {k: success_rate(v) for k, v in sorted(by_task.items())}


def rc(rows: Iterable[MetricRow], **where) -> float:
    """Recovery consistency 1 - population std of R_k over tasks; NaN with no task."""
    rates = list(task_rates(rows, **where).values())
    if not rates:
        return NAN
    mean = sum(rates) / len(rates)
    return 1.0 - math.sqrt(sum((x - mean) ** 2 for x in rates) / len(rates))


@dataclass(frozen=True)
class RDResult:
    rd: float
    m_pre: float
    m_post: float
    n_pre: int  # reruns counted
    n_post: int
    scenes: int  # matched scenes
    m_during: float = NAN
    n_during: int = 0


def rd(rows: Iterable[MetricRow], epsilon: float, **where) -> RDResult:
    """Recovery degradation from the RD reruns matching `where` (matched scenes only)."""
    if epsilon <= 0:
        raise ValueError(f"epsilon must be > 0, got {epsilon}")
    by_scene: dict[str, dict[str, list[MetricRow]]] = defaultdict(lambda: {"pre": [], "during": [], "post": []})
    for r in select(rows, mode="rd", **where):
        phase = _value(r.rd_phase)
        if phase not in ("pre", "during", "post"):
            raise ValueError(f"rd row of scene {r.scene_id} has rd_phase {phase!r}, need pre, during or post")
        by_scene[r.scene_id][phase].append(r)
    matched = [v for v in by_scene.values() if v["pre"] and v["post"]]
    pre, during, post = ([r for v in matched for r in v[ph]] for ph in ("pre", "during", "post"))
    if not matched:
        return RDResult(NAN, NAN, NAN, 0, 0, 0)
    m_pre, m_post = success_rate(pre), success_rate(post)
    return RDResult(1.0 - (m_post + epsilon) / (m_pre + epsilon), m_pre, m_post, len(pre), len(post), len(matched),
                    success_rate(during), len(during))


def counts(rows: Iterable[MetricRow], **where) -> tuple[int, int]:
    """(successes, trials) of the scene trials matching `where`."""
    chosen = select(rows, mode="scene", **where)
    return sum(r.success for r in chosen), len(chosen)
