"""Export of final, reviewed records: one JSON per episode plus one Parquet table.

Inputs: the review database.
Outputs (under `root`, default `<run>/stage3/annotations/`):
  <suite>/<task>/episode_<episode_id>.json   one `records.Annotation` each
  annotations.parquet                         the same records, flat (ANNOTATION_SCHEMA)
  model_vs_truth.json                         when the scripted generator wrote a truth: the
                                              model proposals and final records vs it
                                              (`pipeline.review.truth_view`)
Invariants: only final items are exported (never pending, conflict or excluded ones);
per episode the newest final revision wins; every file is written atomically and
validated against the pydantic model first; the folder mirrors the database exactly
(episode files no longer backed by a final record are removed), so export can be rerun.
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy import select
from sqlalchemy.orm import Session

from pipeline.arrow import arrow_schema
from pipeline.atomic import write_json, write_text, write_with
from pipeline.layout import Stage3Layout
from pipeline.records import Annotation, AnnotationAdjudication, AnnotationProposal, AnnotationReview, Category, Level
from pipeline.review import truth_view
from pipeline.review.audit import iso
from pipeline.review.db import Adjudication, Item, Review, User
from pipeline.vocab import ItemStatus, Resolution

class AnnotationRow(BaseModel):
    """One row of `annotations.parquet`: the headline values of an Annotation, flat."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    key: str
    suite: str
    task: str
    episode_id: str
    revision: int
    fail_time_s: float
    fail_step: int
    recovery_level: Level
    failure_category: Category
    recovery_action: str
    resolution: Resolution
    quarantined: bool
    model_fail_time_s: float | None
    model_recovery_level: Level | None
    model_failure_category: Category | None
    n_reviews: int
    adjudicator: str | None
    json_: str = Field(alias="json")  # the full record, as in the JSON file (`json` is a BaseModel method)


ANNOTATION_SCHEMA = arrow_schema(AnnotationRow)


def file_for(root: Path, a: Annotation) -> Path:
    return Stage3Layout.annotation(root, a.suite, a.task, a.episode_id)


def annotation(s: Session, item: Item) -> Annotation:
    reviews = s.execute(select(Review, User.name).join(User, User.id == Review.reviewer_id)
                        .where(Review.item_id == item.id).order_by(Review.id)).all()
    adj = s.execute(select(Adjudication, User.name).join(User, User.id == Adjudication.adjudicator_id)
                    .where(Adjudication.item_id == item.id)).first()
    p, f, ctx = item.proposal or {}, item.final or {}, item.context or {}
    return Annotation(
        key=item.key, suite=item.suite, task=item.task, episode_id=item.episode_id, revision=item.revision,
        instruction=item.instruction, **{k: f[k] for k in ("fail_time_s", "fail_step", "recovery_level",
                                                            "failure_category", "recovery_action")},
        resolution=item.resolution, quarantined=item.quarantined, quarantine_reason=item.quarantine_reason,
        model_proposal=AnnotationProposal(**{k: p.get(k) for k in AnnotationProposal.model_fields
                                             if k != "schema_version" and p.get(k) is not None}),
        reviews=[AnnotationReview(reviewer=name, decision=r.decision, **(r.values or {}), edited=r.edited,
                                  flag_reason=r.flag_reason, at=iso(r.updated_at)) for r, name in reviews],
        adjudication=None if adj is None else AnnotationAdjudication(
            adjudicator=adj[1], rationale=adj[0].rationale, fields=sorted(adj[0].values), at=iso(adj[0].created_at)),
        scene_bddl=ctx.get("scene_bddl"), scene_state=ctx.get("scene_state"), finalized_at=iso(item.finalized_at),
    )


def final_items(s: Session) -> list[Item]:
    """Per episode key, the newest final revision, unless the adjudicator excluded it."""
    newest: dict[str, Item] = {}
    for item in s.scalars(select(Item).where(Item.status == ItemStatus.final).order_by(Item.key, Item.revision)):
        newest[item.key] = item
    return [i for i in newest.values() if i.resolution != Resolution.excluded and i.final]


def export(s: Session, root: str | Path, run_dir: str | Path | None = None, control_hz: int = 20,
           tau: float = 1.0) -> list[Path]:
    root = Path(root)
    finals = final_items(s)
    records = [annotation(s, item) for item in finals]
    written = []
    for a in records:
        path = file_for(root, a)
        write_json(path, a.model_dump(mode="json"))
        written.append(path)
    keep = {p.resolve() for p in written}
    for old in root.glob(Stage3Layout.ANNOTATION_GLOB) if root.exists() else []:
        if old.resolve() not in keep:
            old.unlink()
    rows = [_row(a).model_dump(mode="json", by_alias=True) for a in records]
    table = pa.Table.from_pylist(rows, schema=ANNOTATION_SCHEMA)
    import pyarrow.parquet as pq

    write_with(root / Stage3Layout.ANNOTATIONS_TABLE, lambda p: pq.write_table(table, p))
    truth = truth_view.compare(finals, run_dir, tau, control_hz) if run_dir is not None else None
    if truth is not None:
        write_json(root / Stage3Layout.MODEL_VS_TRUTH, truth)
    else:
        (root / Stage3Layout.MODEL_VS_TRUTH).unlink(missing_ok=True)
    return written


def _row(a: Annotation) -> AnnotationRow:
    p = a.model_proposal
    return AnnotationRow(
        key=a.key, suite=a.suite, task=a.task, episode_id=a.episode_id, revision=a.revision,
        fail_time_s=a.fail_time_s, fail_step=a.fail_step, recovery_level=a.recovery_level,
        failure_category=a.failure_category, recovery_action=a.recovery_action, resolution=a.resolution,
        quarantined=a.quarantined, model_fail_time_s=p.fail_time_s, model_recovery_level=p.recovery_level,
        model_failure_category=p.failure_category, n_reviews=len(a.reviews),
        adjudicator=a.adjudication.adjudicator if a.adjudication else None,
        json_=json.dumps(a.model_dump(mode="json"), ensure_ascii=False),
    )


def write_schema(path: str | Path) -> Path:
    """The JSON schema of an exported annotation file, generated from `records.Annotation`."""
    schema = Annotation.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "libero-recover final failure annotation"
    write_text(path, json.dumps(schema, indent=2, ensure_ascii=False) + "\n")
    return Path(path)
