"""`recover verify`: every corruption is caught, with a message naming the file; the scenes
run as a Stage, so a rerun checks only what changed and a scene the checks cannot run on
is set aside with the reason.

One release holds one scene per corruption (all of one task), so the whole module builds
the task's environment twice: once for the fixture episode, once for verify.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.release.build import build
from pipeline.release.manifest import MANIFEST_NAME, read_manifest, sha256_file, write_manifest
from pipeline.release.verify import main, verify_release

from tests.release.factories import make_run, npy_bytes, release_config

pytestmark = pytest.mark.sim

BOWLS_ONE_LINE = "akita_black_bowl_1 akita_black_bowl_2 - akita_black_bowl"
BOWLS_TWO_LINES = "akita_black_bowl_1 - akita_black_bowl\n    akita_black_bowl_2 - akita_black_bowl"
PLATE, NO_SUCH_PLATE = "plate_1 - plate", "plate_1 - no_such_plate"  # LIBERO's parser takes it; the model does not build


def _rehash(out: Path) -> None:
    """Make the manifest agree with the files again (a corrupted copy that was re-hashed)."""
    rows = [r.model_copy(update={"bddl_sha256": sha256_file(out / r.bddl_path),
                                 "state_sha256": sha256_file(out / r.state_path)}) for r in read_manifest(out / MANIFEST_NAME)]
    write_manifest(out / MANIFEST_NAME, rows)


@pytest.fixture(scope="module")
def checked(tmp_path_factory, scene_source):
    src = scene_source
    good = npy_bytes(src.failure)
    episodes = ["good", "truncated", "short", "syntax", "split", "solved", "tampered", "unbuildable"]
    scenes = {ep: (npy_bytes(src.satisfied) if ep == "solved" else good, src.bddl_text) for ep in episodes}
    assert PLATE in src.bddl_text
    scenes["unbuildable"] = (good, src.bddl_text.replace(PLATE, NO_SUCH_PLATE))
    run = make_run(tmp_path_factory.mktemp("run"), src, scenes)
    cfg = release_config(run)
    rows = {r.episode_id: r for r in build(cfg)}
    out = run / "release"
    assert BOWLS_ONE_LINE in src.bddl_text
    (out / rows["truncated"].state_path).write_bytes(good[: len(good) // 2])
    (out / rows["short"].state_path).write_bytes(npy_bytes(src.failure[:-3]))
    (out / rows["syntax"].bddl_path).write_text(src.bddl_text.rstrip().removesuffix(")"))
    (out / rows["split"].bddl_path).write_text(src.bddl_text.replace(BOWLS_ONE_LINE, BOWLS_TWO_LINES))
    _rehash(out)
    # tampered after hashing: the manifest keeps the original checksum of the history
    history = out / rows["tampered"].history_paths[0]
    data = bytearray(history.read_bytes())
    data[-1] ^= 0xFF
    history.write_bytes(bytes(data))
    reports, set_problems = verify_release(out, cfg.release)
    by_episode = {r.scene.split("/")[2].removeprefix("episode_"): r for r in reports}
    return out, by_episode, set_problems, cfg, rows


def _problems(checked, episode: str) -> list[str]:
    return checked[1][episode].problems


def _scene_file(checked, episode: str, suffix: str) -> str:
    out = checked[0]
    return str(next((out / "selected_bddl_scenes_libero_spatial").rglob(f"episode_{episode}/*{suffix}")))


def test_verify_passes_an_untouched_scene(checked):
    assert _problems(checked, "good") == []
    assert all(checked[1]["good"].checks.values())
    assert checked[2] == []


def test_verify_reports_a_truncated_npy_naming_the_file(checked):
    (msg,) = _problems(checked, "truncated")
    assert msg.startswith(_scene_file(checked, "truncated", "_sim_state.npy"))
    assert "cannot load state" in msg


def test_verify_rejects_a_state_of_the_wrong_length(checked):
    (msg,) = _problems(checked, "short")
    assert msg.startswith(_scene_file(checked, "short", "_sim_state.npy"))
    assert "state_dim" in msg and str(checked[1]["good"].checks) and "length" in msg


def test_verify_rejects_a_bddl_syntax_error(checked):
    (msg,) = _problems(checked, "syntax")
    assert msg.startswith(_scene_file(checked, "syntax", ".bddl"))
    assert "parser failed" in msg and "parenthesis" in msg


def test_verify_rejects_same_type_objects_on_separate_lines(checked):
    (msg,) = _problems(checked, "split")
    assert msg.startswith(_scene_file(checked, "split", ".bddl"))
    assert "'akita_black_bowl'" in msg and "one line" in msg


def test_verify_rejects_a_scene_whose_goal_already_holds(checked):
    msgs = _problems(checked, "solved")
    assert any(m.startswith(_scene_file(checked, "solved", "_sim_state.npy")) and "goal" in m for m in msgs)
    assert checked[1]["solved"].checks["goal"] is False


def test_verify_detects_a_checksum_mismatch(checked):
    (msg,) = _problems(checked, "tampered")
    assert msg.startswith(_scene_file(checked, "tampered", "_history.npy"))
    assert "SHA-256" in msg and "does not match" in msg


def test_verify_flags_a_stray_scene_file_and_exits_nonzero(checked, capsys):
    out = checked[0]
    stray = out / "selected_bddl_scenes_libero_spatial" / "extra.bddl"
    stray.write_text("(define)")
    try:
        reports, set_problems = verify_release(out)
        assert set_problems == [f"{stray}: scene file not listed in the manifest"]
    finally:
        stray.unlink()


def test_verify_main_exits_nonzero_and_prints_every_problem(checked, capsys, monkeypatch):
    import pipeline.release.verify as verify

    # reuse the module's results instead of rebuilding the environment
    monkeypatch.setattr(verify, "verify_release", lambda d, *a: (list(checked[1].values()), checked[2]))
    assert main(checked[0]) == 1
    text = capsys.readouterr().out
    assert "1/8 scenes pass" in text
    assert text.count("problem") >= 7


def test_verify_reports_a_missing_manifest(tmp_path: Path):
    reports, set_problems = verify_release(tmp_path)
    assert reports == [] and set_problems == [f"{tmp_path / 'scenarios.parquet'}: manifest missing"]


def test_verify_flags_a_stray_file_at_the_top_level_naming_it(checked):
    out = checked[0]
    stray = out / "notes.txt"
    stray.write_text("not part of the release")
    try:
        _, set_problems = verify_release(out)
        assert set_problems == [f"{stray}: not part of a release (stray file at the top level)"]
        assert main(out) == 1
    finally:
        stray.unlink()
    assert verify_release(out)[1] == []


def _markers(out: Path) -> dict[str, int]:
    return {p.stem: p.stat().st_mtime_ns for p in (out / "_build" / "verify" / "_done").glob("*.done")}


def test_a_scene_whose_environment_does_not_build_is_set_aside_naming_the_file(checked):
    out, rows = checked[0], checked[4]
    (msg,) = _problems(checked, "unbuildable")
    assert msg.startswith(f"{out / rows['unbuildable'].bddl_path}: not verified (set aside: KeyError")
    assert "no_such_plate" in msg
    markers = _markers(out)
    assert len(markers) == 7 and not any("unbuildable" in m for m in markers)  # checked again next time


def test_a_rerun_takes_unchanged_scenes_from_their_markers_and_checks_a_changed_one_again(checked):
    out, by_episode, _, cfg, rows = checked
    before = _markers(out)
    state = out / rows["good"].state_path
    original = state.read_bytes()
    try:
        reports, _ = verify_release(out, cfg.release)
        assert {r.scene: r.problems for r in reports} == {r.scene: r.problems for r in by_episode.values()}
        assert _markers(out) == before  # nothing was checked again
        state.write_bytes(original[: len(original) // 2])
        reports, _ = verify_release(out, cfg.release)
        changed = {m for m, t in _markers(out).items() if before[m] != t}
        assert len(changed) == 1 and "good" in changed.pop()
        problems = next(r for r in reports if r.scene == rows["good"].bddl_path).problems
        assert any(m.startswith(f"{state}: SHA-256") for m in problems)
    finally:
        state.write_bytes(original)


def test_the_cli_runs_on_the_configs_executor(checked, tmp_path):
    import yaml
    from typer.testing import CliRunner

    from pipeline.cli import app

    cfg = tmp_path / "verify.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(tmp_path)}, "executor": {"kind": "inline"}}))
    res = CliRunner().invoke(app, ["verify", str(checked[0]), "--config", str(cfg)])
    assert res.exit_code == 1 and "1/8 scenes pass" in res.output, res.output
