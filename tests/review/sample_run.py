"""A tiny synthetic run folder in the real stage-1/stage-2 layouts (no simulator needed).

A test fixture (also used by benchmarks/review_load.py and benchmarks/bad_inputs.py); the
paths come from `pipeline.layout.RunLayout`, like the stages'. Each episode gets a real H.264
MP4 per camera (a moving square, so frame steps are visible), `frames.parquet`, a stage-2
evidence Parquet in EVIDENCE_SCHEMA (with the metadata `pipeline.evidence` writes; columns
this sample does not model are neutral), and a Localization JSON;
`quarantined` episodes get a stage-2 QuarantineEntry instead of a localization.
Output: the list of episode keys written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.atomic import write_json, write_with
from pipeline.layout import RunLayout, episode_key
from pipeline.rendered import stamped
from pipeline.records import (EVIDENCE_SCHEMA, FRAME_SCHEMA, EventKind, Localization, Phases, QuarantineEntry,
                              QuarantineReason, SimEvent)

SUITE, TASK = "libero_spatial", "pick_up_the_black_bowl_and_place_it_on_the_plate"
INSTRUCTION = "pick up the black bowl and place it on the plate"
OBJECTS = ["akita_black_bowl_1", "plate_1", "cookie_box_1"]


def write_video(path: Path, n_frames: int, fps: int, size: int = 64, hue: int = 0) -> None:
    import av

    def encode(tmp: Path) -> None:
        with av.open(str(tmp), "w", format="mp4") as c:
            st = c.add_stream("h264", rate=fps)
            st.width = st.height = size
            st.pix_fmt = "yuv420p"
            st.codec_context.thread_count = 1
            for i in range(n_frames):
                img = np.full((size, size, 3), (40 + hue) % 255, np.uint8)
                x = int((size - 12) * i / max(1, n_frames - 1))
                img[size // 2 - 6: size // 2 + 6, x: x + 12] = (250, 200, 40)
                for p in st.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                    c.mux(p)
            for p in st.encode():
                c.mux(p)

    write_with(path, encode)


def _default(typ: pa.DataType):
    """A neutral value of an Arrow type (for evidence columns this sample does not model)."""
    if pa.types.is_map(typ):
        return [(o, _default(typ.item_type)) for o in OBJECTS]
    if pa.types.is_fixed_size_list(typ):
        return [_default(typ.value_type)] * typ.list_size
    if pa.types.is_list(typ):
        return []
    if pa.types.is_string(typ):
        return ""
    if pa.types.is_boolean(typ):
        return False
    return 0


def _evidence(path: Path, steps: int, hz: int, fail_step: int) -> None:
    """Rows in EVIDENCE_SCHEMA (whatever columns it has now) with a toppled bowl at `fail_step`."""
    import json

    n = steps + 1
    held = [fail_step - 10 <= s < fail_step for s in range(n)]
    moved = [min(1.0, max(0.0, (s - fail_step) / 10)) for s in range(n)]
    known = {
        "step": list(range(n)),
        "time_s": [s / hz for s in range(n)],
        "gripper_opening": [0.01 if h else 0.08 for h in held],
        "gripper_command": [1.0 if h else -1.0 for h in held],
        "grasped": ["akita_black_bowl_1" if h else "" for h in held],
        "contacts": [["akita_black_bowl_1|robot"] if h else (["akita_black_bowl_1|cookie_box_1"] if s >= fail_step else [])
                     for s, h in enumerate(held)],
        "goal_progress": [0.0] * n,
        "displacement": [[("akita_black_bowl_1", 0.12 * m), ("plate_1", 0.0), ("cookie_box_1", 0.05 * m)] for m in moved],
        "tilt_deg": [[("akita_black_bowl_1", 80 * m), ("plate_1", 0.0), ("cookie_box_1", 0.0)] for m in moved],
    }
    cols = {f.name: known.get(f.name, [_default(f.type)] * n) for f in EVIDENCE_SCHEMA}
    meta = dict(EVIDENCE_SCHEMA.metadata or {})
    meta[b"evidence"] = json.dumps({"control_hz": hz, "objects": OBJECTS, "fixtures": ["main_table"],
                                    "goal": [["on", "akita_black_bowl_1", "plate_1"]],
                                    "targets": ["akita_black_bowl_1"], "references": ["plate_1"]}).encode()
    table = pa.table(cols, schema=EVIDENCE_SCHEMA.with_metadata(meta))
    write_with(path, lambda p: pq.write_table(table, p))


def build(run_dir: str | Path, n_episodes: int = 3, n_quarantined: int = 1, steps: int = 60, hz: int = 20,
          fps: int = 10, wrist: bool = True, video_size: int = 64) -> list[str]:
    layout = RunLayout(Path(run_dir))
    keys = []
    for i in range(n_episodes + n_quarantined):
        ep = f"scripted-i{i:02d}-s0"
        key = episode_key(SUITE, TASK, ep)
        keys.append(key)
        files = layout.stage1.episode_of_key(key)
        n_frames = steps * fps // hz + 1
        frames = pa.table({"frame": pa.array(range(n_frames), pa.int32()),
                           "step": pa.array([f * hz // fps for f in range(n_frames)], pa.int32()),
                           "time_s": pa.array([f / fps for f in range(n_frames)], pa.float64())}, schema=stamped(FRAME_SCHEMA))
        write_with(files.frames, lambda p, tb=frames: pq.write_table(tb, p))
        write_video(files.video("agentview"), n_frames, fps, video_size)
        if wrist:
            write_video(files.video("robot0_eye_in_hand"), n_frames, fps, video_size, hue=90)
        fail_step = steps // 2 + 2 * i
        _evidence(layout.stage2.evidence_of_key(key), steps, hz, fail_step)
        if i >= n_episodes:
            q = QuarantineEntry(key=key, stage="stage2", source="openai", reason=QuarantineReason.no_json,
                                detail="the answer held no JSON object", raw_text="I think it fails around there.",
                                model="Qwen/Qwen3.5-27B", prompt_name="localize.v1.zh", prompt_hash="ab12cd34")
            write_json(layout.stage2.abs(layout.stage2.quarantine_for_key(key)), q.model_dump(mode="json"))
            continue
        loc = Localization(
            key=key, suite=SUITE, task=TASK, episode_id=ep, instruction=INSTRUCTION, source="simstate",
            fail_time_s=fail_step / hz, fail_step=fail_step,
            phases=Phases(pre=(0, fail_step), during=(fail_step, min(steps, fail_step + 10)),
                          post=(min(steps, fail_step + 10), steps + 1)),
            scene_bddl=f"scenes/{SUITE}/{TASK}/{ep}.bddl", scene_state=f"scenes/{SUITE}/{TASK}/{ep}.npy",
            events=[SimEvent(step=fail_step, time_s=fail_step / hz, kind=EventKind.object_toppled, object="akita_black_bowl_1",
                             detail="tilted 80 degrees")],
        )
        write_json(layout.stage2.localization_of_key(key), loc.model_dump(mode="json"))
    return keys
