"""Stage 2's compiled outputs: the localization table, the agreement report, the summary.

Inputs: the per-episode Localization / QuarantineEntry JSON files under the stage-2 folder.
Outputs (rewritten from those files on every run, so they always match them):
    localizations.parquet            one LocalizationRow per Localization (LOCALIZATION_SCHEMA)
    agreement.json + agreement.png   when a VLM ran beside simstate: MAE and shares within
                                     +-0.5 s / +-1 s of |vlm - simstate| (pipeline.labelers.vlm.agreement),
                                     and a histogram of the signed differences
    summary.json                     counts: scenes, quarantined by reason, by onset event kind;
                                     set_aside + input_faults: episodes quarantined for a bad
                                     input (key, reason, file, field) or an unexpected error
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import BaseModel, ConfigDict

from pipeline.arrow import I64, arrow_schema
from pipeline.atomic import write_json, write_with
from pipeline.errors import invalid_file
from pipeline.layout import Stage2Layout
from pipeline.records import EventKind, Localization, QuarantineEntry, QuarantineReason


def _read(model, path: Path):
    try:
        return model.model_validate_json(path.read_text())
    except (ValueError, OSError) as e:  # ValidationError is a ValueError; a bad file is named, not a traceback
        raise invalid_file(path, e) from e


def load_outputs(stage2: Path) -> tuple[list[Localization], list[QuarantineEntry]]:
    paths = Stage2Layout(Path(stage2))
    locs = [_read(Localization, p) for p in sorted(paths.localizations_dir.rglob("*.json"))]
    quar = [_read(QuarantineEntry, p) for p in sorted(paths.quarantine_dir.rglob("*.json"))]
    return locs, quar


class LocalizationRow(BaseModel):
    """One row of `localizations.parquet`: a Localization with its phases flattened, the kind
    of the event at the onset, and the events as JSON text."""

    model_config = ConfigDict(extra="forbid")

    schema_version: I64
    key: str
    suite: str
    task: str
    episode_id: str
    instruction: str
    source: str
    model: str | None
    prompt_name: str | None
    prompt_hash: str | None
    raw_text: str | None
    fail_time_s: float
    fail_step: I64
    scene_step: I64
    scene_bddl: str
    scene_state: str
    history: str | None
    simstate_time_s: float | None
    evidence: str | None
    pre_start: I64
    pre_end: I64
    during_start: I64
    during_end: I64
    post_start: I64
    post_end: I64
    onset_kind: EventKind | None
    events: str  # JSON list of SimEvents


# Declared as pyarrow inferred it when this file had no schema (int64, every column nullable,
# no metadata), so readers see the same types; a column that was all-null in a run (typed
# `null` then) now carries its declared type.
LOCALIZATION_SCHEMA = arrow_schema(LocalizationRow, metadata=None, nullable=True)


def localization_row(loc: Localization) -> LocalizationRow:
    row = loc.model_dump(exclude={"phases", "events"})
    for name in ("pre", "during", "post"):
        row[f"{name}_start"], row[f"{name}_end"] = getattr(loc.phases, name)
    row["onset_kind"] = next((e.kind for e in loc.events if e.step == loc.fail_step), None)
    row["events"] = json.dumps([e.model_dump(mode="json") for e in loc.events])
    return LocalizationRow.model_validate(row)


def localization_table(locs: list[Localization]) -> pa.Table:
    rows = [localization_row(loc).model_dump(mode="json") for loc in locs]
    return pa.Table.from_pylist(rows, schema=LOCALIZATION_SCHEMA)


def write_agreement(stage2: Path, locs: list[Localization]) -> dict | None:
    vlm = [loc for loc in locs if loc.source != "simstate"]
    if not vlm:
        return None
    from pipeline.labelers.vlm.agreement import agreement

    pairs = [(loc.fail_time_s, loc.simstate_time_s) for loc in vlm if loc.simstate_time_s is not None]
    result = agreement(pairs).model_dump()
    result.update(vlm_localized=len(vlm), simstate_missing=len(vlm) - len(pairs),
                  sources=sorted({f"{loc.source}:{loc.model}" for loc in vlm}))
    write_json(Stage2Layout(Path(stage2)).agreement, result)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3), dpi=120)
    diffs = [a - b for a, b in pairs]
    ax.hist(diffs or [0.0], bins=max(5, min(40, len(diffs))), color="#4477aa")
    for x in (-1, -0.5, 0.5, 1):
        ax.axvline(x, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("VLM onset - simstate onset (s)")
    ax.set_ylabel("episodes")
    mae = "n/a" if result["mae_s"] is None else f"{result['mae_s']:.2f} s"
    ax.set_title(f"n={result['n']}  MAE={mae}")
    fig.tight_layout()
    write_with(Stage2Layout(Path(stage2)).agreement_figure, lambda p: fig.savefig(p, format="png"))
    plt.close(fig)
    return result


def write_reports(stage2: Path) -> dict:
    locs, quar = load_outputs(stage2)
    table = localization_table(locs)
    write_with(Stage2Layout(Path(stage2)).localizations_table, lambda p: pq.write_table(table, p))
    summary = {
        "scenes": len(locs),
        "quarantined": len(quar),
        "quarantine_reasons": dict(Counter(q.reason for q in quar)),
        # set aside for a bad input (a stage-1 file or manifest cell) or an unexpected error:
        # the episodes a fix and a rerun can still bring back
        "set_aside": len(faults := [q for q in quar if q.file or q.reason == QuarantineReason.episode_error]),
        "input_faults": [{"key": q.key, "reason": q.reason, "file": q.file, "field": q.field} for q in faults],
        "onset_kinds": dict(Counter(r for r in table.column("onset_kind").to_pylist()) if locs else {}),
        "agreement": write_agreement(stage2, locs),
    }
    write_json(Stage2Layout(Path(stage2)).summary, summary)
    return summary
