"""Queue statistics from the database: reviewer agreement and model-vs-final quality.

Inputs: a read session, the time tolerance tau.
Outputs: `summary()` (JSON-ready dict), `plot()` (PNG: level and category confusion
matrices per characterizer model/prompt, and failure-time errors per localizer).
Invariants: flags carry no values and are left out of agreement; superseded revisions
and items still collecting reviews (`blindness.closed`) are left out; model-vs-final uses final, non-excluded items only, grouped by the
model and prompt version that produced the proposal.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from pipeline.review import blindness, stats
from pipeline.review.db import Item, Review
from pipeline.review.fields import CATEGORIES, LEVELS, same_action
from pipeline.vocab import ItemStatus


def _version(p: dict | None) -> str:
    p = p or {}
    name = p.get("model") or p.get("source") or "unknown"
    prompt = p.get("prompt_name")
    return f"{name} / {prompt}@{(p.get('prompt_hash') or '')[:8]}" if prompt else name


def _agreement(units: dict[int, list[dict]], tau: float) -> dict:
    multi = [u for u in units.values() if len(u) >= 2]
    out: dict = {"items": len(multi)}
    for field, metric, order in (("recovery_level", "ordinal", LEVELS), ("failure_category", "nominal", None)):
        vals = [[v[field] for v in u] for u in multi]
        k = {len(u) for u in vals}
        kappa, kind = stats.NAN, None
        if k == {2}:
            kappa, kind = stats.cohen_kappa([u[0] for u in vals], [u[1] for u in vals]), "cohen"
        elif len(k) == 1 and vals:
            labels = order or CATEGORIES
            kappa, kind = stats.fleiss_kappa([[u.count(lab) for lab in labels] for u in vals]), "fleiss"
        out[field] = {
            "kappa": stats.clean(kappa), "kappa_kind": kind,
            "alpha": stats.clean(stats.krippendorff_alpha(vals, metric, order)), "alpha_metric": metric,
            "percent_agreement": stats.clean(sum(len(set(u)) == 1 for u in vals) / len(vals) if vals else stats.NAN),
        }
    times = [[v["fail_time_s"] for v in u] for u in multi]
    out["fail_time_s"] = {"tau_s": tau, "within_tau": stats.clean(stats.within_tolerance(times, tau)),
                          "alpha_interval": stats.clean(stats.krippendorff_alpha(times, "interval"))}
    actions = [[v["recovery_action"] for v in u] for u in multi]
    same = [all(same_action(u[0], x) for x in u[1:]) for u in actions]
    out["recovery_action"] = {"percent_agreement": stats.clean(sum(same) / len(same) if same else stats.NAN)}
    return out


def _model_quality(items: list[Item], tau: float) -> dict:
    chars: dict[str, list] = defaultdict(list)
    locs: dict[str, list] = defaultdict(list)
    for it in items:
        p, f = it.proposal or {}, it.final or {}
        if p.get("recovery_level") is not None:
            chars[_version(p.get("characterizer") or p)].append((f, p))
        if p.get("fail_time_s") is not None:
            locs[_version(p.get("localizer") or p)].append(round(p["fail_time_s"] - f["fail_time_s"], 3))
    by_char = []
    for ver, rows in sorted(chars.items()):
        lv = [(f["recovery_level"], p["recovery_level"]) for f, p in rows]
        cat = [(f["failure_category"], p["failure_category"]) for f, p in rows]
        by_char.append({
            "version": ver, "n": len(rows),
            "level": {"labels": LEVELS, "matrix": stats.confusion(lv, LEVELS),
                      "accuracy": stats.clean(sum(a == b for a, b in lv) / len(lv))},
            "category": {"labels": CATEGORIES, "matrix": stats.confusion(cat, CATEGORIES),
                         "accuracy": stats.clean(sum(a == b for a, b in cat) / len(cat))},
        })
    by_loc = [{"version": ver, "n": len(errs), "errors_s": errs,
               "mean_abs_error_s": stats.clean(sum(abs(e) for e in errs) / len(errs)),
               "within_tau": stats.clean(sum(abs(e) <= tau + 1e-9 for e in errs) / len(errs))}
              for ver, errs in sorted(locs.items())]
    return {"by_characterizer": by_char, "by_localizer": by_loc}


def current_items(s: Session) -> list[Item]:
    """Every item that is not a superseded revision."""
    return list(s.scalars(select(Item).where(Item.status != ItemStatus.superseded).order_by(Item.id)))


def summary(s: Session, tau: float) -> dict:
    units: dict[int, list[dict]] = defaultdict(list)
    rows = s.execute(
        select(Review.item_id, Review.values).join(Item, Item.id == Review.item_id)
        .where(Item.status != ItemStatus.superseded, blindness.closed(), Review.values.is_not(None))
        .order_by(Review.id)
    ).all()
    for item_id, values in rows:
        if values:
            units[item_id].append(values)
    finals = s.scalars(select(Item).where(Item.status == ItemStatus.final, Item.final.is_not(None))).all()
    return {"agreement": _agreement(units, tau), "model_vs_final": _model_quality(list(finals), tau)}


def plot(summary_: dict, path: str | Path) -> Path:
    """One PNG: a row per characterizer version (level, category), then time-error histograms."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mq = summary_["model_vs_final"]
    chars, locs = mq["by_characterizer"], mq["by_localizer"]
    rows = max(1, len(chars)) + (1 if locs else 0)
    fig, axes = plt.subplots(rows, 2, figsize=(12, 4.6 * rows), squeeze=False)
    for r, grp in enumerate(chars or [None]):
        for c, field in enumerate(("level", "category")):
            ax = axes[r][c]
            if grp is None:
                ax.text(0.5, 0.5, "no final records yet", ha="center", va="center")
                ax.axis("off")
                continue
            m, labels = grp[field]["matrix"], grp[field]["labels"]
            ax.imshow(m, cmap="Blues")
            short = [lab.replace("_failure", "").replace("_or_interaction", "/int.")[:14] for lab in labels]
            ax.set_xticks(range(len(labels)), short, rotation=40, ha="right", fontsize=8)
            ax.set_yticks(range(len(labels)), short, fontsize=8)
            for i, row in enumerate(m):
                for j, v in enumerate(row):
                    if v:
                        ax.text(j, i, str(v), ha="center", va="center", fontsize=9)
            ax.set_xlabel("model")
            ax.set_ylabel("final (reviewed)")
            ax.set_title(f"{field}: {grp['version']}\nn={grp['n']} accuracy={grp[field]['accuracy']}", fontsize=9)
    if locs:
        ax = axes[-1][0]
        for grp in locs:
            ax.hist(grp["errors_s"], bins=20, alpha=0.6, label=f"{grp['version']} (n={grp['n']})")
        ax.set_xlabel("model failure time - final failure time (s)")
        ax.set_ylabel("episodes")
        ax.legend(fontsize=8)
        ax.set_title("failure-time error by localizer", fontsize=9)
        axes[-1][1].axis("off")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    from pipeline.atomic import write_with

    write_with(path, lambda p: fig.savefig(p, dpi=90, format="png"))
    plt.close(fig)
    return path
