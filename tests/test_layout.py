"""The run layout: the paths of one key, the key's one spelling, and that no other module of
`pipeline/` spells a run folder or run file name (an AST scan of the source)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from pipeline.layout import (
    RunLayout,
    episode_key,
    key_of_unit,
    parse_key,
    parse_scene_bddl,
    scene_files,
    scene_id,
    scene_rel,
    unit_id,
)
from pipeline.records import EpisodeRecord

PIPELINE = Path(__file__).resolve().parents[1] / "pipeline"
KEY = "libero_goal/open_the_middle_drawer_of_the_cabinet/scripted-i03-s7"


def _record(**kw) -> EpisodeRecord:
    base = dict(suite="libero_goal", task="open_the_middle_drawer_of_the_cabinet", task_index=0, instruction="x",
                episode_id="scripted-i03-s7", init_state=3, policy="scripted", policy_kind="scripted", seed=7,
                chunk_size=1, horizon=10, settle_steps=0, steps=5, success=False, wall_time_s=0.1, state_dim=9,
                path=f"episodes/{KEY}", videos={"agentview": "video_agentview.mp4"})
    return EpisodeRecord(**{**base, **kw})


def test_layout_names_every_file_of_an_episode(tmp_path):
    run = RunLayout(tmp_path)
    rel = lambda p: p.relative_to(tmp_path).as_posix()  # noqa: E731
    rec = _record()
    ep = run.stage1.episode(rec)
    assert rel(run.stage1.manifest) == "stage1/episodes.parquet"
    assert rel(run.stage1.summary) == "stage1/summary.json"
    assert run.stage1.episode_rel(KEY) == rec.path
    assert [rel(p) for p in (ep.states, ep.steps, ep.frames, ep.truth, ep.video("robot0_eye_in_hand"))] == [
        f"stage1/episodes/{KEY}/{n}" for n in
        ("states.npy", "steps.parquet", "frames.parquet", "truth.parquet", "video_robot0_eye_in_hand.mp4")]
    assert run.stage1.video(rec, "agentview") == ep.video("agentview")
    assert run.stage1.video(rec, "robot0_eye_in_hand") is None  # not rendered: the manifest row says so
    s2 = run.stage2
    assert [s2.evidence(rec).as_posix(), s2.localization(rec).as_posix(), s2.quarantine(rec).as_posix(),
            s2.vlm(rec).as_posix()] == [f"evidence/{KEY}.parquet", f"localizations/{KEY}.json",
                                        f"quarantine/{KEY}.json", f"vlm/{KEY}.json"]
    assert s2.abs(s2.evidence(rec)) == s2.evidence_of_key(KEY)
    assert s2.abs(s2.localization(rec)) == s2.localization_of_key(KEY)
    scene = s2.scene(KEY, 42)
    folder = "stage2/selected_bddl_scenes_libero_goal/open_the_middle_drawer_of_the_cabinet/episode_scripted-i03-s7"
    assert [rel(p) for p in (scene.bddl, scene.state, scene.history, scene.history_frames)] == [
        f"{folder}/step_0042.bddl", f"{folder}/step_0042_sim_state.npy", f"{folder}/step_0042_history.npz",
        f"{folder}/step_0042_history_frames.npz"]
    s3 = run.stage3
    assert rel(s3.characterization(KEY)) == f"stage3/characterizations/{KEY}.json"
    assert rel(s3.quarantine(KEY)) == f"stage3/quarantine/{KEY}.json"
    assert rel(s3.review_db) == "stage3/review.sqlite"
    assert rel(s3.annotation(s3.annotations, *parse_key(KEY))) == (
        "stage3/annotations/libero_goal/open_the_middle_drawer_of_the_cabinet/episode_scripted-i03-s7.json")
    assert rel(scene_files(s3.reviewed_scenes, KEY, 42).bddl) == (
        f"stage3/reviewed_scenes/{folder.removeprefix('stage2/')}/step_0042.bddl")
    assert [rel(run.release.manifest), rel(run.release.card), rel(run.release.quarantine_log)] == [
        "release/scenarios.parquet", "release/README.md", "release/_build/quarantine.jsonl"]
    assert rel(run.eval.trial("u1")) == "eval/trials/u1.parquet" and rel(run.bench("simstate")) == "bench/localize_simstate"


def test_release_folder_follows_the_config(tmp_path):
    from pipeline.config import Config

    cfg = Config.model_validate({"run": {"output_dir": str(tmp_path / "run")}})
    assert RunLayout.of(cfg).release.root == tmp_path / "run" / "release"
    cfg = Config.model_validate({"run": {"output_dir": str(tmp_path / "run")},
                                 "release": {"output_dir": str(tmp_path / "elsewhere")}})
    assert RunLayout.of(cfg).release.manifest == tmp_path / "elsewhere" / "scenarios.parquet"


def test_key_unit_id_and_scene_path_round_trip():
    suite, task, ep = parse_key(KEY)
    assert episode_key(suite, task, ep) == KEY == _record().key
    assert unit_id(KEY) == f"{suite}__{task}__{ep}" and key_of_unit(unit_id(KEY)) == KEY
    assert parse_scene_bddl(f"{scene_rel(KEY)}/step_0042.bddl") == (KEY, 42)
    assert scene_id(KEY, 42) == f"{KEY}/step_0042"
    assert parse_scene_bddl("selected_bddl_scenes_x/t/ep_1/step_0042.bddl") is None  # no episode_ prefix


def test_a_key_without_three_parts_is_refused_by_name():
    with pytest.raises(ValueError, match="libero_goal/only_two"):
        parse_key("libero_goal/only_two")
    with pytest.raises(ValueError, match="a__b"):
        key_of_unit("a__b")


# ---- nothing outside pipeline/layout.py builds a run path ------------------------------------
# folder names of a run that must not appear as an operand of `/`, and file names of a run that
# must not appear as a string at all (an f-string's literal parts included)
FOLDERS = {"stage1", "stage2", "stage3", "release", "eval", "bench", "episodes", "evidence", "localizations",
           "quarantine", "characterizations", "annotations", "reviewed_scenes", "trials", "vlm", "errors", "scenes"}
FILES = {"episodes.parquet", "summary.json", "states.npy", "actions.npy", "steps.parquet", "frames.parquet", "truth.parquet",
         "scenarios.parquet", "review.sqlite", "review_status.json", "annotations.parquet", "localizations.parquet",
         "agreement.json", "agreement.png", "metrics.json", "report.md", "quarantine.jsonl", "config.resolved.yaml",
         "SHA256SUMS", "README.md", "_build"}
PATTERNS = ("selected_bddl_scenes_", "_sim_state.npy", "stage1/", "stage2/", "stage3/")
# LIBERO's own assets folder (pipeline/sim), not a run's
ALLOWED = {("sim/libero_setup.py", "scenes")}


def _strings(node: ast.AST) -> list[str]:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, ast.JoinedStr):
        return [v.value for v in node.values if isinstance(v, ast.Constant) and isinstance(v.value, str)]
    return []


def hand_built_paths(source: str) -> list[tuple[int, str]]:
    """(line, literal) of every run folder or file name a module spells itself."""
    tree = ast.parse(source)
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
                  and n.body and isinstance(n.body[0], ast.Expr)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div):
            found += [(node.lineno, s) for side in (node.left, node.right) for s in _strings(side) if s in FOLDERS]
        if isinstance(node, (ast.Constant, ast.JoinedStr)) and id(node) not in docstrings:
            found += [(node.lineno, s) for s in _strings(node)
                      if s in FILES or (s.startswith(PATTERNS) or s.endswith(PATTERNS)) and " " not in s
                      or s == "video_" or s.startswith("video_") and s.endswith(".mp4")]
    return found


def test_the_scan_sees_hand_built_paths():
    old = '''
def f(run_dir, suite, task, ep, cam):
    a = run_dir / "stage2" / "evidence" / suite / task / f"{ep}.parquet"
    b = run_dir / "stage1" / "episodes.parquet"
    c = ep_dir / f"video_{cam}.mp4"
    d = f"selected_bddl_scenes_{suite}/{task}/episode_{ep}"
    return "stage1/episodes.parquet"
'''
    assert {s for _, s in hand_built_paths(old)} == {
        "stage2", "evidence", "stage1", "episodes.parquet", "video_", "selected_bddl_scenes_", "stage1/episodes.parquet"}


def test_no_module_outside_the_layout_builds_a_run_path():
    offenders = []
    for path in sorted(PIPELINE.rglob("*.py")):
        rel = path.relative_to(PIPELINE).as_posix()
        if rel == "layout.py":
            continue
        offenders += [f"pipeline/{rel}:{line}: {s!r}" for line, s in hand_built_paths(path.read_text())
                      if (rel, s) not in ALLOWED]
    assert not offenders, "run paths built outside pipeline/layout.py:\n" + "\n".join(offenders)


# ---- docs/data-format.md is checked against the layout and the schemas ----------------------
DOC = PIPELINE.parent / "docs" / "data-format.md"


def _doc_rows() -> list[tuple[str, str]]:
    """(path template, RunLayout call) of every table row that names a call."""
    rows = []
    for line in DOC.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 2 and cells[0].startswith("`") and cells[1].startswith("`"):
            rows.append((cells[0].strip("`"), cells[1].strip("`")))
    return rows


def test_every_path_in_the_data_format_page_is_the_layouts(tmp_path):
    import pipeline.layout as layout_module

    rec = _record()
    suite, task, ep = parse_key(KEY)
    names = {**{k: v for k, v in vars(layout_module).items() if not k.startswith("_")},
             "L": RunLayout(tmp_path), "rec": rec, "key": KEY, "camera": "agentview", "step": 42, "uid": "u1",
             "localizer": "simstate"}
    fill = {"<key>": KEY, "<suite>": suite, "<task>": task, "<episode_id>": ep, "<camera>": "agentview",
            "<NNNN>": "0042", "<unit>": "u1", "<localizer>": "simstate"}
    rows = _doc_rows()
    assert len(rows) >= 40, f"{DOC}: expected the path tables, found {len(rows)} rows"
    for template, call in rows:
        want = template
        for k, v in fill.items():
            want = want.replace(k, v)
        got = eval(call, names).relative_to(tmp_path).as_posix()  # noqa: S307 - our own doc, in a test
        assert got == want.rstrip("/"), f"{DOC}: row {template!r}: {call} gives {got!r}"


def test_the_data_format_page_lists_every_parquet_column():
    import re

    from pipeline.eval.records import EVAL_SCHEMA
    from pipeline.records import EPISODE_SCHEMA, EVIDENCE_SCHEMA, FRAME_SCHEMA, STEP_SCHEMA
    from pipeline.release.manifest import SCENARIO_SCHEMA
    from pipeline.review.export import ANNOTATION_SCHEMA

    schemas = {"EPISODE_SCHEMA": EPISODE_SCHEMA, "STEP_SCHEMA": STEP_SCHEMA, "FRAME_SCHEMA": FRAME_SCHEMA,
               "EVIDENCE_SCHEMA": EVIDENCE_SCHEMA, "SCENARIO_SCHEMA": SCENARIO_SCHEMA,
               "ANNOTATION_SCHEMA": ANNOTATION_SCHEMA, "EVAL_SCHEMA": EVAL_SCHEMA}
    listed = {m[1]: re.findall(r"`([^`]+)`", m[2])
              for m in re.finditer(r"^- `(\w+_SCHEMA)` \([^)]*\) columns: (.*)$", DOC.read_text(), re.M)}
    assert listed == {n: s.names for n, s in schemas.items()}, f"{DOC}: column lists differ from the schemas"
