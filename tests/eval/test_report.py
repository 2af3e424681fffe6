from __future__ import annotations

import json

from pipeline.config import EvalConfig
from pipeline.eval.report import compute, write_report
from tests.eval.test_metrics import row


def _rows() -> list:
    rows = []
    for chunk, wins in ((8, [True, False, True, True]), (16, [False, False, True, False])):
        for i, w in enumerate(wins):
            rows.append(row(w, task=f"t{i % 2}", level="L1" if i < 2 else "L3", chunk_size=chunk,
                            gripper="open" if i % 2 else "closed"))
    rows += [row(True, mode="rd", rd_phase="pre", scene="s1"), row(False, mode="rd", rd_phase="post", scene="s1")]
    return rows


def test_report_writes_tables_figures_and_metrics_with_dashes_for_empty_cells(tmp_path):
    ecfg = EvalConfig(chunk_sizes=[8, 16], epsilon=1e-3)
    data = write_report(_rows(), ecfg, tmp_path, scenes_dir="x", planned=12)
    md = (tmp_path / "report.md").read_text()
    # chunk 8: L1 1/2, L3 2/2; L2 and L4 keep their columns, empty
    assert "| suite | L1 | L2 | L3 | L4 | all |" in md
    assert "| libero_spatial | 50.0 (2) | — | 100.0 (2) | — | 75.0 (4) |" in md
    spatial = data["policies"]["scripted"]["rsr_suite_level"]["libero_spatial"]
    assert spatial == {"L1": 0.5, "L2": None, "L3": 1.0, "L4": None, "all": 0.75}
    assert data["policies"]["scripted"]["chunk_sweep"] == {"8": 0.75, "16": 0.25}
    assert data["policies"]["scripted"]["rd"]["all"]["rd"] == round(1 - (0 + 1e-3) / (1 + 1e-3), 6)
    assert data["policies"]["scripted"]["rd"]["all"]["scenes"] == 1
    assert "### Chunk-size sweep" in md and "| 16 | 25.0 (4) |" in md
    for png in ("rsr_heatmap.png", "gripper.png", "chunk_sweep.png"):
        assert (tmp_path / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((tmp_path / "metrics.json").read_text())["policies"]["scripted"]["rsr"] == 0.75


def test_undefined_cells_are_null_in_metrics_and_a_dash_in_the_table(tmp_path):
    rows = [row(True, suite="libero_spatial", level="L1"), row(False, suite="libero_goal", level="L2")]
    data = write_report(rows, EvalConfig(), tmp_path)
    grid = data["policies"]["scripted"]["rsr_suite_level"]
    assert grid["libero_goal"]["L1"] is None and grid["libero_spatial"]["L2"] is None
    assert data["policies"]["scripted"]["rd"]["all"]["rd"] is None  # no RD reruns at all
    md = (tmp_path / "report.md").read_text()
    assert "| libero_spatial | 100.0 (1) | — | — | — | 100.0 (1) |" in md
    assert "| libero_goal | — | 0.0 (1) | — | — | 0.0 (1) |" in md


def test_compute_separates_policies():
    rows = [row(True, policy="a"), row(False, policy="b")]
    data = compute(rows, EvalConfig())
    assert data["policies"]["a"]["rsr"] == 1.0 and data["policies"]["b"]["rsr"] == 0.0


def test_the_summary_puts_the_recovery_expert_as_a_reference_row_beside_the_plain_expert(tmp_path):
    rows = [row(w, policy="scripted") .model_copy(update={"policy_kind": "scripted"}) for w in (True, False, False, False)]
    rows += [row(w, policy="recovery", level="L3") .model_copy(update={"policy_kind": "recovery"}) for w in (True, True, True, False)]
    rows += [row(False, policy="pi0") .model_copy(update={"policy_kind": "openpi"})]
    write_report(rows, EvalConfig(), tmp_path)
    md = (tmp_path / "report.md").read_text()
    assert "| policy | kind | L1 | L2 | L3 | L4 | all |" in md
    assert "| `scripted` | scripted expert (reference) | 25.0 (4) | — | — | — | 25.0 (4) |" in md
    assert "| `recovery` | recovery expert (reference) | — | — | 75.0 (4) | — | 75.0 (4) |" in md
    assert "| `pi0` | openpi | 0.0 (1) |" in md


def test_official_init_state_trials_are_libero_success_beside_rsr_and_stay_out_of_the_rsr_tables(tmp_path):
    rows = [row(True, level="L1"), row(False, level="L2")]
    rows += [row(w, mode="official", level=None) for w in (True, True, True, False)]
    data = write_report(rows, EvalConfig(), tmp_path)
    res = data["policies"]["scripted"]
    assert res["libero_success"] == {"libero_spatial": 0.75, "all": 0.75} and res["rsr"] == 0.5
    md = (tmp_path / "report.md").read_text()
    assert "unlabeled" not in md  # official trials have no level: no column for them
    assert "| `scripted` | libero_spatial | 75.0 (4) | 50.0 (2) |" in md
    assert (tmp_path / "libero_vs_rsr.png").read_bytes()[:4] == b"\x89PNG"
