"""Evaluation report: markdown tables, `metrics.json` and PNG figures, from rows only.

Inputs: evaluation rows (`records.MetricRow`, from `records.read_rows`), the `EvalConfig` (epsilon, chunk sizes).
Outputs in `out`: `report.md`; `metrics.json` (NaN written as null); `rsr_heatmap.png`
(RSR per suite x level, one panel per policy); `gripper.png` (open vs closed);
`rd_phases.png` (RD rerun success before / during / after the failure, per suite);
`libero_vs_rsr.png` (standard LIBERO success from the official init states beside RSR, per
policy and suite, when official trials ran);
`chunk_sweep.png` (RSR per chunk size, when more than one was run).

Tables use the first configured chunk size, except the sweep. Rates are percentages; an
undefined rate (empty subset) is "—", and the trial count is shown beside every cell.
"""

from __future__ import annotations

import math
from pathlib import Path

from pipeline.atomic import write_json, write_text, write_with
from pipeline.config import SUITES, EvalConfig, reported_suites
from pipeline.eval import metrics as M
from pipeline.eval.records import MetricRow
from pipeline.layout import EvalLayout
from pipeline.vocab import Level

LEVELS = tuple(Level)  # the main table's columns, always


def pct(x: float) -> str:
    return "—" if x is None or math.isnan(x) else f"{100 * x:.1f}"


def _cell(rows, **where) -> str:
    """Rate (trials) of the scene trials matching `where`."""
    wins, n = M.counts(rows, **where)
    return _rate(wins, n)


def _rate(wins: int, n: int) -> str:
    return "—" if n == 0 else f"{pct(wins / n)} ({n})"


def _nan_none(x: float) -> float | None:
    return None if x is None or math.isnan(x) else round(float(x), 6)


def _ordered(values, order) -> list:
    present = set(values)
    return [v for v in order if v in present] + sorted(v for v in present if v not in order and v is not None)


def _levels(rows) -> list[str | None]:
    """L1..L4 always (the main table's columns), then any other level, then unlabeled (of
    the scene trials: official-init-state trials have no level)."""
    rows = M.select(rows, mode="scene")
    lv = list(LEVELS) + [v for v in _ordered({r.level for r in rows}, LEVELS) if v not in LEVELS]
    return lv + ([None] if any(r.level is None for r in rows) else [])


def _table(header: list[str], body: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in body]) + "\n"


def suite_rows(rows) -> list[tuple[str, tuple[str, ...]]]:
    """(row name, member suites): each suite, and LIBERO-100 (libero_100) beside its halves,
    pooled from their trials (`config.reported_suites`)."""
    return reported_suites(_ordered({r.suite for r in rows}, SUITES))


def compute(rows: list[MetricRow], ecfg: EvalConfig) -> dict:
    """Every number of the report, as plain data (NaN -> None)."""
    chunk = ecfg.chunk_sizes[0]
    out: dict = {"chunk_size": chunk, "epsilon": ecfg.epsilon, "policies": {}}
    groups = suite_rows(rows)
    for pol in _ordered({r.policy for r in rows}, []):
        base = M.select(rows, policy=pol)
        main = M.select(base, chunk_size=chunk)
        res = {
            "rsr": _nan_none(M.rsr(main)),
            "rsr_suite_level": {s: {lv or "unlabeled": _nan_none(M.rsr(main, suite=m, level=lv)) for lv in _levels(main)}
                                | {"all": _nan_none(M.rsr(main, suite=m))} for s, m in groups},
            "rsr_level": {lv or "unlabeled": _nan_none(M.rsr(main, level=lv)) for lv in _levels(main)},
            "rc": {s: _nan_none(M.rc(main, suite=m)) for s, m in groups} | {"all": _nan_none(M.rc(main))},
            "libero_success": {s: _nan_none(M.libero_success(main, suite=m)) for s, m in groups}
            | {"all": _nan_none(M.libero_success(main))},
            "task_rates": {f"{s}/{t}": _nan_none(v) for (s, t), v in M.task_rates(main).items()},
            "rd": {},
            "gripper": {g: _nan_none(M.rsr(main, gripper=g)) for g in ("open", "closed")},
            "chunk_sweep": {str(c): _nan_none(M.rsr(base, chunk_size=c)) for c in ecfg.chunk_sizes},
        }
        for s, m in groups + [("all", None)]:
            r = M.rd(main, ecfg.epsilon, **({} if m is None else {"suite": m}))
            res["rd"][s] = {"rd": _nan_none(r.rd), "m_pre": _nan_none(r.m_pre),
                            "m_during": _nan_none(r.m_during), "m_post": _nan_none(r.m_post),
                            "n_pre": r.n_pre, "n_during": r.n_during, "n_post": r.n_post, "scenes": r.scenes}
        out["policies"][pol] = res
    return out


# how the summary names a policy kind; the privileged-state experts are reference rows
KIND_LABEL = {"scripted": "scripted expert (reference)", "recovery": "recovery expert (reference)"}


def summary_table(rows: list[MetricRow], data: dict, contexts: dict[str, str] | None = None) -> str:
    """RSR per policy x level, one row per policy: the experts sit beside the evaluated policies,
    and a policy evaluated with several temporal contexts (one name each) has a row per variant."""
    main = M.select(rows, mode="scene", chunk_size=data["chunk_size"])
    lvls = _levels(main)
    body = []
    for pol in data["policies"]:
        sel = M.select(main, policy=pol)
        kinds = sorted({r.policy_kind or "" for r in sel} - {""})
        kind = ", ".join(KIND_LABEL.get(k, k) for k in kinds) or "—"
        ctx = [(contexts or {}).get(pol, "none")] if contexts else []
        body.append([f"`{pol}`", kind] + ctx + [_cell(sel, level=lv) for lv in lvls] + [_cell(sel)])
    return _table(["policy", "kind"] + (["temporal context"] if contexts else []) + [lv or "unlabeled" for lv in lvls]
                  + ["all"], body)


def libero_table(rows: list[MetricRow], data: dict) -> str:
    """Standard LIBERO success beside RSR, a row per policy x suite (LIBERO-100 included)."""
    main = M.select(rows, chunk_size=data["chunk_size"])
    body = []
    for pol in data["policies"]:
        sel = M.select(main, policy=pol)
        for s, m in suite_rows(sel) + [("all", None)]:
            where = {} if m is None else {"suite": m}
            official = M.select(sel, mode="official", **where)
            body.append([f"`{pol}`", "**all**" if m is None else _name(s, m),
                         _rate(sum(r.success for r in official), len(official)), _cell(sel, **where)])
    return _table(["policy", "suite", "LIBERO success", "RSR"], body)


def _contexts(ecfg: EvalConfig) -> dict[str, str] | None:
    """policy name -> its temporal context, when any policy is evaluated with one."""
    from pipeline.eval.plan import context_of, policy_name

    ctx = {policy_name(p): context_of(p, ecfg) for p in ecfg.policies}
    return ctx if any(v != "none" for v in ctx.values()) else None


def _name(suite: str, members: tuple[str, ...]) -> str:
    return suite if members == (suite,) else f"*{suite}*"  # a union: LIBERO-100


def markdown(rows: list[MetricRow], ecfg: EvalConfig, data: dict, header: str = "") -> str:
    chunk = data["chunk_size"]
    groups = suite_rows(rows)
    parts = ["# Recovery evaluation\n\n", header, "\n",
             f"Rates in %, trials in parentheses; — = no trials in that subset. Chunk size {chunk} unless noted; "
             f"RD epsilon {ecfg.epsilon:g}; RC uses the population std of task rates.\n",
             *(["*libero_100* is LIBERO-100, libero_10 and libero_90 together: its rates pool their trials "
                "(not an average of the two rates).\n"] if any(m != (s,) for s, m in groups) else []),
             "\n## RSR per policy × level\n\nThe experts read privileged simulator state: they are references "
             "(what a competent recovering policy scores), not contestants.\n\n", summary_table(rows, data, _contexts(ecfg))]
    official = M.select(rows, mode="official", chunk_size=chunk)
    if official:
        parts += ["\n## LIBERO success vs RSR per policy × suite\n\nLIBERO success: the policy from LIBERO's official "
                  "init states of the evaluated tasks (unperturbed, gripper open, `eval.official_trials` per task); "
                  "RSR: from the recovery scenes of the same tasks.\n\n", libero_table(rows, data)]
    for pol, res in data["policies"].items():
        main = M.select(rows, policy=pol, chunk_size=chunk)
        lvls = _levels(main)
        head = ["suite"] + [lv or "unlabeled" for lv in lvls] + ["all"]
        body = [[_name(s, m)] + [_cell(main, suite=m, level=lv) for lv in lvls] + [_cell(main, suite=m)]
                for s, m in groups]
        body.append(["**all**"] + [_cell(main, level=lv) for lv in lvls] + [_cell(main)])
        parts += [f"\n## Policy `{pol}`\n\n### RSR per suite × level\n\n", _table(head, body)]
        rd_body = [[k, pct(v["m_pre"]), pct(v["m_during"]), pct(v["m_post"]),
                    "—" if v["rd"] is None else f"{v['rd']:.3f}",
                    f"{v['scenes']} / {v['n_pre']} / {v['n_during']} / {v['n_post']}"] for k, v in res["rd"].items()]
        parts += ["\n### RD per suite\n\nReruns from states along the source rollout, by stage 2's phase: before "
                  "the failure (pre), while it unfolds (during), after it (post); RD = 1 - (M_post + ε)/(M_pre + ε).\n\n",
                  _table(["suite", "M_pre", "M_during", "M_post", "RD", "scenes / pre / during / post reruns"], rd_body)]
        rc_body = [[k, "—" if v is None else f"{v:.3f}"] for k, v in res["rc"].items()]
        parts += ["\n### RC per suite\n\n", _table(["suite", "RC"], rc_body)]
        g_body = [[_name(s, m)] + [_cell(main, suite=m, gripper=g) for g in ("open", "closed")] for s, m in groups]
        g_body.append(["**all**"] + [_cell(main, gripper=g) for g in ("open", "closed")])
        parts += ["\n### Gripper initialization: open vs closed\n\n", _table(["suite", "open", "closed"], g_body)]
        if len(ecfg.chunk_sizes) > 1:
            base = M.select(rows, policy=pol)
            c_body = [[str(c), _cell(base, chunk_size=c)] for c in ecfg.chunk_sizes]
            parts += ["\n### Chunk-size sweep\n\n", _table(["chunk size", "RSR"], c_body)]
    return "".join(parts)


def plots(data: dict, ecfg: EvalConfig, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    pols = list(data["policies"])
    if not pols:
        return []
    written = []
    fig, axes = plt.subplots(1, len(pols), figsize=(4.5 * len(pols), 3.2), squeeze=False)
    for ax, pol in zip(axes[0], pols, strict=True):
        grid = data["policies"][pol]["rsr_suite_level"]
        suites, cols = list(grid), (list(next(iter(grid.values()))) if grid else [])
        vals = np.array([[np.nan if grid[s][c] is None else 100 * grid[s][c] for c in cols] for s in suites])
        ax.set_facecolor("#e6e6e6")  # undefined cells (no trials) show grey
        ax.imshow(np.ma.masked_invalid(vals), vmin=0, vmax=100, cmap="viridis", aspect="auto")
        ax.set_xticks(range(len(cols)), cols)
        ax.set_yticks(range(len(suites)), suites)
        for i in range(len(suites)):
            for j in range(len(cols)):
                v = vals[i, j]
                ax.text(j, i, "—" if np.isnan(v) else f"{v:.0f}", ha="center", va="center",
                        color="black" if np.isnan(v) or v > 60 else "white")
        ax.set_title(f"RSR % — {pol}")
    fig.tight_layout()
    write_with(out / "rsr_heatmap.png", lambda p: fig.savefig(p, dpi=120))
    plt.close(fig)
    written.append("rsr_heatmap.png")

    fig, ax = plt.subplots(figsize=(1.5 + 1.6 * len(pols), 3))
    x = np.arange(len(pols))
    for k, g in enumerate(("open", "closed")):
        v = [data["policies"][p]["gripper"][g] for p in pols]
        ax.bar(x + (k - 0.5) * 0.38, [np.nan if a is None else 100 * a for a in v], 0.38, label=g)
    ax.set_xticks(x, pols)
    ax.set_ylim(0, 100)
    ax.set_ylabel("RSR %")
    ax.legend(title="gripper")
    fig.tight_layout()
    write_with(out / "gripper.png", lambda p: fig.savefig(p, dpi=120))
    plt.close(fig)
    written.append("gripper.png")

    if any(v is not None for p in pols for v in data["policies"][p]["libero_success"].values()):
        written.append(_libero_plot(data, pols, out, plt, np))

    if any(v["scenes"] for p in pols for v in data["policies"][p]["rd"].values()):
        written.append(_rd_phase_plot(data, pols, out, plt, np))

    if len(ecfg.chunk_sizes) > 1:
        fig, ax = plt.subplots(figsize=(4.5, 3))
        for pol in pols:
            sweep = data["policies"][pol]["chunk_sweep"]
            ax.plot(ecfg.chunk_sizes, [np.nan if sweep[str(c)] is None else 100 * sweep[str(c)]
                                       for c in ecfg.chunk_sizes], marker="o", label=pol)
        ax.set_xscale("log", base=2)
        ax.set_xticks(ecfg.chunk_sizes, [str(c) for c in ecfg.chunk_sizes])
        ax.set_ylim(0, 100)
        ax.set_xlabel("chunk size")
        ax.set_ylabel("RSR %")
        ax.legend()
        fig.tight_layout()
        write_with(out / "chunk_sweep.png", lambda p: fig.savefig(p, dpi=120))
        plt.close(fig)
        written.append("chunk_sweep.png")
    return written


PHASES = ("pre", "during", "post")


def _libero_plot(data: dict, pols: list[str], out: Path, plt, np) -> str:
    """Standard LIBERO success (official init states) beside RSR, bars per suite, one panel
    per policy: how much of a policy's benchmark success survives its own failures."""
    fig, axes = plt.subplots(1, len(pols), figsize=(1.2 + 1.1 * len(data["policies"][pols[0]]["libero_success"])
                                                     * len(pols), 3.4), squeeze=False)
    for ax, pol in zip(axes[0], pols, strict=True):
        res = data["policies"][pol]
        suites = list(res["libero_success"])
        rsr = {**{s: v["all"] for s, v in res["rsr_suite_level"].items()}, "all": res["rsr"]}
        x = np.arange(len(suites))
        for k, (label, vals) in enumerate((("LIBERO (official init)", res["libero_success"]), ("LIBERO-Recover RSR", rsr))):
            ys = [np.nan if vals.get(s) is None else 100 * vals[s] for s in suites]
            ax.bar(x + (k - 0.5) * 0.38, ys, 0.38, label=label)
        ax.set_xticks(x, suites, rotation=30, ha="right", fontsize=8)
        ax.set_ylim(0, 125)  # headroom: the legend sits above the bars
        ax.set_yticks(range(0, 101, 20))
        ax.set_ylabel("success %")
        ax.set_title(f"LIBERO vs RSR — {pol}")
        ax.legend(fontsize=7, ncol=2, loc="upper center")
    fig.tight_layout()
    write_with(out / "libero_vs_rsr.png", lambda p: fig.savefig(p, dpi=120))
    plt.close(fig)
    return "libero_vs_rsr.png"


def _rd_phase_plot(data: dict, pols: list[str], out: Path, plt, np) -> str:
    """Success of the RD reruns per phase (pre / during / post), one line per suite, one
    panel per policy: the three-phase drop."""
    fig, axes = plt.subplots(1, len(pols), figsize=(4.2 * len(pols), 3.2), squeeze=False)
    for ax, pol in zip(axes[0], pols, strict=True):
        for suite, v in data["policies"][pol]["rd"].items():
            if not v["scenes"]:
                continue
            ys = [np.nan if v[f"m_{ph}"] is None else 100 * v[f"m_{ph}"] for ph in PHASES]
            ax.plot(range(3), ys, marker="o", label=suite, linestyle="--" if suite == "all" else "-")
        ax.set_xticks(range(3), PHASES)
        ax.set_ylim(-5, 105)
        ax.set_ylabel("rerun success %")
        ax.set_title(f"RD phases — {pol}")
        ax.legend(fontsize=7)
    fig.tight_layout()
    write_with(out / "rd_phases.png", lambda p: fig.savefig(p, dpi=120))
    plt.close(fig)
    return "rd_phases.png"


def write_report(rows: list[MetricRow], ecfg: EvalConfig, out: str | Path, scenes_dir=None,
                 problems: list[str] | None = None, planned: int | None = None, split_note: str | None = None) -> dict:
    out = Path(out)
    data = compute(rows, ecfg)
    scene_rows = M.select(rows, mode="scene")
    header = (f"Scenes: `{scenes_dir}` ({len({r.scene_id for r in scene_rows})} evaluated); "
              f"trials recorded: {len(rows)}" + (f" of {planned} planned" if planned is not None else "") + ".\n")
    if split_note:
        header += f"\nEvaluated: {split_note}.\n"
    if problems:
        header += "\nProblems (skipped):\n\n" + "".join(f"- {p}\n" for p in problems)
    figs = plots(data, ecfg, out)
    md = markdown(rows, ecfg, data, header) + "".join(f"\n![{f}]({f})\n" for f in figs)
    write_text(EvalLayout(out).report, md)
    write_json(EvalLayout(out).metrics, data)
    return data
