"""Printing `recover review status`: queue counts, agreement, model quality, and model and
reviewers vs the generator's truth when there is one (rich tables).

Inputs: the dict from `report.summary` plus `counts`. Output: text on the console; every
cell goes through `terminal.cell` (model and prompt names come from model output and config).
"""

from __future__ import annotations

from rich.console import Console
from rich.table import Table

from pipeline.review.terminal import cell
from pipeline.vocab import ItemStatus


def _f(x) -> str:
    return "—" if x is None else f"{x:.3f}"


def render(out: dict, console: Console | None = None) -> None:
    console = console or Console()
    counts = out["counts"]
    t = Table(title=f"review queue: {counts['total']} items ({counts['quarantined']} quarantined)")
    t.add_column("status")
    t.add_column("items", justify="right")
    for status in ItemStatus:
        if counts["by_status"].get(status):
            t.add_row(cell(status), str(counts["by_status"][status]))
    console.print(t)

    ag = out["agreement"]
    t = Table(title=f"reviewer agreement ({ag['items']} items with 2+ reviews)")
    for col in ("field", "kappa", "Krippendorff alpha", "agreement"):
        t.add_column(col)
    for field in ("recovery_level", "failure_category"):
        a = ag[field]
        t.add_row(field, f"{_f(a['kappa'])} ({a['kappa_kind'] or '—'})", f"{_f(a['alpha'])} ({a['alpha_metric']})",
                  _f(a["percent_agreement"]))
    ft = ag["fail_time_s"]
    t.add_row("fail_time_s", "—", f"{_f(ft['alpha_interval'])} (interval)", f"{_f(ft['within_tau'])} within ±{ft['tau_s']} s")
    t.add_row("recovery_action", "—", "—", _f(ag["recovery_action"]["percent_agreement"]))
    console.print(t)

    mq = out["model_vs_final"]
    t = Table(title="model vs final")
    for col in ("proposal by", "n", "level acc.", "category acc.", "time MAE s", "time within τ"):
        t.add_column(col)
    for g in mq["by_characterizer"]:
        t.add_row(cell(g["version"]), str(g["n"]), _f(g["level"]["accuracy"]), _f(g["category"]["accuracy"]), "", "")
    for g in mq["by_localizer"]:
        t.add_row(cell(g["version"] + " (times)"), str(g["n"]), "", "", _f(g["mean_abs_error_s"]), _f(g["within_tau"]))
    console.print(t)

    truth = out.get("model_vs_truth")
    if truth:
        t = Table(title=f"model and reviewers vs the generator's truth (onset within ±{truth['tau_s']} s)")
        for col in ("records", "n", "onset within τ", "onset MAE s", "level agr.", "category agr."):
            t.add_column(col)
        for name, label in (("model", "model proposal"), ("final", "final (reviewed)")):
            g = truth[name]
            t.add_row(label, str(g["n"]), _f(g["onset_within_tau"]), _f(g["onset_mae_s"]), _f(g["level_agreement"]),
                      _f(g["category_agreement"]))
        console.print(t)
