"""An existing run's frames made by the old renderer: refused by what shows them, redrawn by
`recover stage1 --rerender` from the logged states (no physics), then accepted."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from pipeline.config import load_config
from pipeline.errors import FatalError
from pipeline.layout import RunLayout
from pipeline.records import read_episodes
from pipeline.rendered import frames_version, require_current_frames, run_frame_tables
from pipeline.sim.render import RENDERER_VERSION

sys.path.insert(0, str(Path(__file__).parent))
import toy_policy  # noqa: E402


def _age(frames: Path) -> None:
    """Make a frame table look like the old renderer's (no version in its metadata)."""
    table = pq.read_table(frames)
    pq.write_table(table.replace_schema_metadata({k: v for k, v in table.schema.metadata.items()
                                                  if k != b"renderer_version"}), frames)


@pytest.mark.sim
def test_old_frames_are_refused_then_rerendered_from_states_without_physics(tmp_path):
    from pipeline.stage1.rerender import run as rerender
    from pipeline.stage1.run import run as stage1
    from pipeline.stage1.video import read_video

    cfg_path = tmp_path / "c.yaml"
    cfg_path.write_text(yaml.safe_dump({
        "run": {"name": "rr", "output_dir": str(tmp_path / "run"), "seed": 0},
        "tasks": {"suites": ["libero_spatial"], "max_tasks_per_suite": 1, "init_states": [0]},
        "executor": {"kind": "inline", "workers": 1},
        "stage1": {"policy": {"kind": "scripted", "name": "drift"},
                   "rollout": {"horizon": 20, "chunk_size": 8, "settle_steps": 2},
                   "video": {"cameras": ["agentview"], "fps": 5, "resolution": 64, "render": "all"}},
    }))
    cfg = load_config(cfg_path)
    stage1(cfg, policy_factory=toy_policy.make)
    (frames,) = run_frame_tables(cfg)
    assert frames_version(frames) == RENDERER_VERSION
    rec = read_episodes(RunLayout.of(cfg).stage1.manifest)[0]
    video = RunLayout.of(cfg).stage1.video(rec, "agentview")
    fresh, states_before = read_video(video), np.load(frames.parent / "states.npy")

    _age(frames)
    video.write_bytes(b"old renderer")  # what it drew does not matter: it is redrawn
    with pytest.raises(FatalError, match=r"renderer version 1.*recover stage1 --rerender"):
        require_current_frames(run_frame_tables(cfg), "the review server")

    assert rerender(cfg) == 1
    assert frames_version(frames) == RENDERER_VERSION
    assert all(np.array_equal(a, b) for a, b in zip(read_video(video), fresh, strict=True))
    assert np.array_equal(np.load(frames.parent / "states.npy"), states_before)  # no physics ran
    require_current_frames(run_frame_tables(cfg), "the review server")
    assert rerender(cfg) == 0  # a third call finds nothing to do


def test_lerobot_export_refuses_to_resume_over_episodes_an_older_renderer_drew(tmp_path):
    from pipeline.atomic import Completions
    from pipeline.release.lerobot_export import ExportEpisode, ExportStage, ExportUnit, refuse_old_renders

    ep = ExportEpisode("s/t/e", "libero_spatial", "t", "do it", tmp_path, 3)
    units = [ExportUnit(i, 3 * i, 0, ep, ("m", "k")) for i in range(2)]
    stage = ExportStage(str(tmp_path / "rollouts"), str(tmp_path / "_work"), 64, "standard", units)
    marks = Completions(stage.root)
    marks.mark_done(stage.marker_id(units[0]), {"inputs": stage.fingerprint(units[0])})  # drawn by this renderer
    refuse_old_renders(stage, units)
    marks.mark_done(stage.marker_id(units[1]), {})  # a marker from before renderer versions were recorded
    with pytest.raises(FatalError, match=r"1 episode\(s\).*older renderer.*recover export-lerobot"):
        refuse_old_renders(stage, units)
    # this renderer, but the export's first convention (frames right side up, grip-site axis-angle)
    from pipeline.sim.render import RENDERER_VERSION

    marks.mark_done(stage.marker_id(units[1]), {"inputs": {"renderer_version": RENDERER_VERSION}})
    with pytest.raises(FatalError, match=r"1 episode\(s\).*older image and state convention"):
        refuse_old_renders(stage, units)
