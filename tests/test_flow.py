"""`recover run` on the smoke config: stops at review, goes on after it, then has nothing to do."""

from __future__ import annotations

import uuid
from pathlib import Path

import httpx
import pytest
import yaml
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.flow import STEPS

pytestmark = [pytest.mark.sim, pytest.mark.slow, pytest.mark.timeout(1800)]
REPO = Path(__file__).parents[1]


def _recover_run(cfg: Path) -> str:
    result = CliRunner().invoke(app, ["run", "--config", str(cfg)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    return " ".join(result.output.split())  # rich wraps long lines


def _review_everything(cfg_path: Path) -> int:
    """Two people accept every proposal (flag a quarantined item) over the review API, as on the page."""
    from pipeline.config import load_config
    from pipeline.review.api import create_app
    from pipeline.review.auth import add_user
    from pipeline.review.server import ThreadedServer, engine_for, settings

    cfg = load_config(cfg_path)
    engine = engine_for(cfg)
    tokens = [add_user(engine, name, "reviewer") for name in ("ann", "bob")]
    decisions = 0
    with ThreadedServer(create_app(Path(cfg.out), engine, settings(cfg))) as srv:
        for token in tokens:
            c = httpx.Client(base_url=srv.url, headers={"Authorization": f"Bearer {token}"}, timeout=30)
            while (item := c.post("/api/queue/next").json()["item"]) is not None:
                iid = item["id"] if isinstance(item, dict) else item
                view = c.get(f"/api/items/{iid}").json()
                body = {"decision": "flag", "reason": "quarantined"} if view.get("quarantined") else {"decision": "accept"}
                r = c.post(f"/api/items/{iid}/review", json={**body, "version": view.get("version", 0),
                                                              "idempotency_key": uuid.uuid4().hex})
                assert r.status_code == 200, r.text
                decisions += 1
    return decisions


def test_recover_run_stops_at_review_goes_on_after_it_and_then_has_nothing_to_do(tmp_path):
    smoke = yaml.safe_load((REPO / "configs" / "smoke.yaml").read_text())
    smoke["run"]["output_dir"] = str(tmp_path / "run")
    # the smoke run, with one demo per scene and small LeRobot frames: the test is about the walk.
    # Every scene on the train side, so there are demos to record however few scenes the
    # generator leaves (its two scenes of version 5 both drew the eval side: no demos step ran)
    smoke["release"] = {"recovery_demos": 1, "recovery_demo_tries": 2, "lerobot_image_size": 64,
                        "lerobot_render_quality": "fast", "split": {"train_share": 1.0}}
    cfg = tmp_path / "smoke.yaml"
    cfg.write_text(yaml.safe_dump(smoke))
    run = tmp_path / "run"

    first = _recover_run(cfg)
    assert "stopped at human review" in first and "await review" in first
    assert f"recover run --config {cfg}" in first and "release, demos, export-lerobot" in first
    assert (run / "stage3" / "review.sqlite").is_file() and not (run / "release").exists()

    assert _review_everything(cfg) > 0
    second = _recover_run(cfg)
    for name in ("review-export", "release", "demos", "export-lerobot"):
        assert f"{name} (recover " in second  # each ran, in the declared order
    assert second.index("release (recover") < second.index("demos (recover") < second.index("export-lerobot (recover")
    assert "stage1: up to date" in second and "nothing awaits review" in second
    assert (run / "release" / "scenarios.parquet").is_file() and (run / "recoveries" / "demos.parquet").is_file()
    assert (run / "lerobot" / "rollouts" / "meta" / "info.json").is_file()
    assert sorted(p.name for p in (run / "pipeline" / "_done").iterdir()) == [
        "export-lerobot.done", "release.done", "review-export.done"]

    third = _recover_run(cfg)
    assert "nothing to do" in third and " (recover " not in third
    assert all(f"{s.name}: up to date" in third for s in STEPS if s.gate is None)
