"""Closed sets of values are string enums: a record refuses a value outside its vocabulary,
naming the field, and a valid record's JSON is the same text as with plain strings."""

from __future__ import annotations

import json

import pytest
from pydantic import ValidationError

from pipeline.records import AnnotationReview, QuarantineEntry, SimEvent
from pipeline.release.manifest import ScenarioRow
from pipeline.vocab import Decision, EventKind, QuarantineReason


@pytest.mark.parametrize(("build", "field"), [
    (lambda: SimEvent(step=1, time_s=0.05, kind="object_exploded"), "kind"),
    (lambda: QuarantineEntry(key="s/t/e", stage="stage2", source="simstate", reason="felt_wrong"), "reason"),
    (lambda: AnnotationReview(reviewer="ann", decision="maybe", at="2025-01-01T00:00:00Z"), "decision"),
    (lambda: ScenarioRow.model_validate({"level": "L5"}), "level"),
])
def test_a_value_outside_the_vocabulary_is_refused_naming_its_field(build, field):
    with pytest.raises(ValidationError) as err:
        build()
    assert field in {e["loc"][0] for e in err.value.errors()}


def test_enum_members_serialize_as_the_plain_strings_they_replaced():
    ev = SimEvent(step=3, time_s=0.15, kind=EventKind.grasp_lost, object="bowl")
    assert ev.model_dump_json() == SimEvent.model_validate_json(ev.model_dump_json()).model_dump_json()
    assert json.loads(ev.model_dump_json())["kind"] == "grasp_lost" and f"{ev.kind}" == "grasp_lost"
    q = QuarantineEntry(key="s/t/e", stage="stage2", source="simstate", reason="no_failure_found")
    assert q.reason is QuarantineReason.no_failure_found and q.reason == "no_failure_found"
    assert json.dumps({"d": Decision.flag}) == '{"d": "flag"}'
