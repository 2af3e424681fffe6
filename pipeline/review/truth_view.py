"""Model vs the generator's truth, beside model vs reviewers, for `recover review status`
and the review export.

Inputs: the queue's items (their model proposal and, once reviewed, their final record) and
the run folder, where the scripted generator wrote `truth.parquet` beside each episode's
steps (`<run>/stage1/episodes/<suite>/<task>/<episode_id>/truth.parquet`; derived by
`pipeline.truth.derive`). Output of `compare()`: None when no item has a truth (openpi
runs, sample runs), else for the model proposal and for the final record: how many have a
truth, onset within +-tau of the truth, onset mean absolute error, level and category
agreement; plus one row per episode. The truth is read here only: it is never stored in
the review database nor sent to the review page (reviewers judge independently).
"""

from __future__ import annotations

from pathlib import Path

from pipeline.layout import RunLayout
from pipeline.truth.derive import EpisodeTruth, TruthError, episode_truth


def truth_for(run_dir: str | Path, key: str, control_hz: int = 20) -> EpisodeTruth | None:
    """The episode's truth, or None (no truth file, no failed attempt, an unusable record)."""
    layout = RunLayout(Path(run_dir))
    path = layout.stage1.episode_of_key(key).truth
    if not path.is_file():
        return None
    try:
        return episode_truth(path, key, control_hz, layout.stage2.evidence_of_key(key))
    except TruthError:
        return None


def _figures(pairs: list[tuple[dict, EpisodeTruth]], tau: float) -> dict:
    timed = [(r, t) for r, t in pairs if r.get("fail_time_s") is not None]
    errs = [abs(r["fail_time_s"] - t.onset_time_s) for r, t in timed]
    labelled = [(r, t) for r, t in pairs if r.get("recovery_level") is not None]

    def share(hits: int, n: int) -> float | None:
        return round(hits / n, 4) if n else None

    return {
        "n": len(pairs),
        "onset_within_tau": share(sum(e <= tau + 1e-9 for e in errs), len(errs)),
        "onset_mae_s": round(sum(errs) / len(errs), 3) if errs else None,
        "level_agreement": share(sum(r["recovery_level"] == t.level for r, t in labelled), len(labelled)),
        "category_agreement": share(sum(r["failure_category"] == t.category for r, t in labelled), len(labelled)),
    }


def compare(items, run_dir: str | Path, tau: float, control_hz: int = 20) -> dict | None:
    """Figures of the model proposals and of the final records against the truth; `items`
    need `key`, `proposal` and `final` (review.db.Item rows)."""
    model, final, rows = [], [], []
    for it in items:
        t = truth_for(run_dir, it.key, control_hz)
        if t is None:
            continue
        p, f = it.proposal or {}, it.final or {}
        if p.get("fail_time_s") is not None or p.get("recovery_level") is not None:
            model.append((p, t))
        if f:
            final.append((f, t))
        rows.append({"key": it.key, "truth_time_s": t.onset_time_s, "truth_level": t.level,
                     "truth_category": t.category, "truth_outcome": t.outcome,
                     "model_time_s": p.get("fail_time_s"), "model_level": p.get("recovery_level"),
                     "model_category": p.get("failure_category"), "final_time_s": f.get("fail_time_s"),
                     "final_level": f.get("recovery_level"), "final_category": f.get("failure_category")})
    if not rows:
        return None
    return {"tau_s": tau, "model": _figures(model, tau), "final": _figures(final, tau), "episodes": rows}
