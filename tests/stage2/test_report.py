"""Stage 2's compiled outputs refuse a per-episode file they cannot read, naming it."""

from __future__ import annotations

import json

import pytest

from pipeline.errors import InputError
from pipeline.records import QuarantineEntry
from pipeline.stage2.report import write_reports


def test_a_stage2_file_that_is_not_its_record_is_an_input_error_naming_file_and_field(tmp_path):
    q = QuarantineEntry(key="s/t/e0", stage="stage2", source="simstate", reason="not_settled")
    good = tmp_path / "quarantine" / "s" / "t" / "e0.json"
    good.parent.mkdir(parents=True)
    good.write_text(q.model_dump_json())
    bad = tmp_path / "localizations" / "s" / "t" / "e1.json"
    bad.parent.mkdir(parents=True)
    bad.write_text(json.dumps({"key": "s/t/e1", "suite": "s", "task": "t", "episode_id": "e1", "instruction": "x",
                               "source": "simstate", "fail_time_s": "soon", "fail_step": 3,
                               "phases": {"pre": [0, 3], "during": [3, 5], "post": [5, 9]},
                               "scene_bddl": "a.bddl", "scene_state": "a.npy"}))
    with pytest.raises(InputError) as got:
        write_reports(tmp_path)
    assert (got.value.file, got.value.field) == (str(bad), "fail_time_s")
    bad.write_text("{not json")
    with pytest.raises(InputError, match="e1.json"):
        write_reports(tmp_path)
    assert not (tmp_path / "summary.json").exists()  # nothing half-written from a bad set
