"""The LeRobot v2.1 on-disk format: paths, feature declarations, stats, metadata files.

Pure formatting, no simulator: `pipeline.release.lerobot_export` renders the frames and
calls these. Layout (one dataset folder):
    data/chunk-000/episode_000000.parquet            one row per frame (20 Hz)
    videos/chunk-000/<video key>/episode_000000.mp4  one file per camera and episode
    meta/info.json, meta/episodes.jsonl, meta/episodes_stats.jsonl, meta/tasks.jsonl
    meta/stats.json                                  dataset-wide stats (older v2.x readers want it)
Invariants: episode i lives in chunk i // CHUNKS_SIZE; `index` runs over the whole dataset;
per-episode stats hold min/max/mean/std/count for every feature (images per channel in
[0, 1], shaped (3, 1, 1)), as LeRobot's own writer computes them.
"""

from __future__ import annotations

import json
from pathlib import Path

from typing import Annotated

import numpy as np
import pyarrow as pa
from annotated_types import Len
from pydantic import BaseModel, ConfigDict, Field

from pipeline.arrow import F32, I64, arrow_schema
from pipeline.atomic import write_text

CODEBASE_VERSION = "v2.1"
CHUNKS_SIZE = 1000
FPS = 20
DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
# LeRobot key -> our camera: the names LeRobot's LIBERO env gives policies (`image`, `image2`;
# its docs' HuggingFaceVLA/libero), so a policy trained here reads them unrenamed
VIDEO_KEYS = {"observation.images.image": "agentview", "observation.images.image2": "robot0_eye_in_hand"}
STATE_NAMES = ["x", "y", "z", "axis_angle1", "axis_angle2", "axis_angle3", "gripper_left", "gripper_right"]
ACTION_NAMES = ["dx", "dy", "dz", "droll", "dpitch", "dyaw", "gripper"]
ACTION_F64 = "action_float64"
# the arm's joint states beside the end-effector state, under the keys of LIBERO's LeRobot
# datasets (HuggingFaceVLA/libero): robot0's 7 joint positions (base to wrist) and the two
# finger joint positions; from the recorded MuJoCo states, like everything else here
JOINT_KEY, GRIPPER_KEY = "observation.states.joint_state", "observation.states.gripper_state"
JOINT_NAMES = [f"joint_{i}" for i in range(7)]
GRIPPER_NAMES = ["gripper_left", "gripper_right"]


def data_path(ep: int) -> str:
    return DATA_PATH.format(episode_chunk=ep // CHUNKS_SIZE, episode_index=ep)


def video_path(ep: int, key: str) -> str:
    return VIDEO_PATH.format(episode_chunk=ep // CHUNKS_SIZE, video_key=key, episode_index=ep)


def features(size: int) -> dict:
    video_info = {"video.fps": float(FPS), "video.height": size, "video.width": size, "video.channels": 3,
                  "video.codec": "h264", "video.pix_fmt": "yuv420p", "video.is_depth_map": False, "has_audio": False}
    out = {k: {"dtype": "video", "shape": [size, size, 3], "names": ["height", "width", "channel"], "info": video_info}
           for k in VIDEO_KEYS}
    out["observation.state"] = {"dtype": "float32", "shape": [8], "names": STATE_NAMES}
    out[JOINT_KEY] = {"dtype": "float32", "shape": [7], "names": JOINT_NAMES}
    out[GRIPPER_KEY] = {"dtype": "float32", "shape": [2], "names": GRIPPER_NAMES}
    out["action"] = {"dtype": "float32", "shape": [7], "names": ACTION_NAMES}
    # the same actions exactly as the simulator stepped them: these replay bit for bit
    out[ACTION_F64] = {"dtype": "float64", "shape": [7], "names": ACTION_NAMES}
    for k in ("timestamp",):
        out[k] = {"dtype": "float32", "shape": [1], "names": None}
    for k in ("frame_index", "episode_index", "index", "task_index"):
        out[k] = {"dtype": "int64", "shape": [1], "names": None}
    return out


class LeRobotFrame(BaseModel):
    """One row of a LeRobot data file (`features` declares the same columns for readers)."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    observation_state: Annotated[list[F32], Len(8, 8)] = Field(alias="observation.state")
    joint_state: Annotated[list[F32], Len(7, 7)] = Field(alias=JOINT_KEY)
    gripper_state: Annotated[list[F32], Len(2, 2)] = Field(alias=GRIPPER_KEY)
    action: Annotated[list[F32], Len(7, 7)]
    action_float64: Annotated[list[float], Len(7, 7)]  # `action` before rounding: what was stepped
    timestamp: F32
    frame_index: I64
    episode_index: I64
    index: I64
    task_index: I64


# LeRobot's own writer leaves every column nullable and the schema without metadata
FRAME_SCHEMA = arrow_schema(LeRobotFrame, metadata=None, nullable=True)


def frame_table(states: np.ndarray, actions: np.ndarray, ep: int, start: int, task_index: int,
                joints: np.ndarray) -> pa.Table:
    """`states`: the 8-D end-effector states (their last two: the fingers); `joints`: the arm's 7
    joint positions per frame; `actions`: float64 as stepped (`action` holds them rounded to
    float32, `action_float64` exactly)."""
    n = len(states)

    def fixed(a: np.ndarray) -> pa.FixedSizeListArray:
        a = np.asarray(a, dtype=np.float32)
        return pa.FixedSizeListArray.from_arrays(pa.array(a.reshape(-1), pa.float32()), a.shape[1])

    return pa.table({
        "observation.state": fixed(states),
        JOINT_KEY: fixed(joints),
        GRIPPER_KEY: fixed(np.asarray(states)[:, 6:8]),
        "action": fixed(actions),
        ACTION_F64: pa.FixedSizeListArray.from_arrays(pa.array(np.asarray(actions, dtype=np.float64).reshape(-1),
                                                               pa.float64()), 7),
        "timestamp": pa.array(np.arange(n, dtype=np.float32) / FPS, pa.float32()),
        "frame_index": pa.array(np.arange(n), pa.int64()),
        "episode_index": pa.array(np.full(n, ep), pa.int64()),
        "index": pa.array(np.arange(start, start + n), pa.int64()),
        "task_index": pa.array(np.full(n, task_index), pa.int64()),
    }, schema=FRAME_SCHEMA)


def _stats(x: np.ndarray) -> dict:
    x = np.asarray(x, dtype=np.float64)
    x = x.reshape(len(x), -1) if x.ndim > 1 else x.reshape(-1, 1)
    return {"min": x.min(0).tolist(), "max": x.max(0).tolist(), "mean": x.mean(0).tolist(),
            "std": x.std(0).tolist(), "count": [int(len(x))]}


def image_stats(frames: np.ndarray) -> dict:
    """Per-channel stats of (n, H, W, 3) uint8 frames in [0, 1], shaped (3, 1, 1)."""
    x = frames.astype(np.float64) / 255.0
    per = {"min": x.min((0, 1, 2)), "max": x.max((0, 1, 2)), "mean": x.mean((0, 1, 2)), "std": x.std((0, 1, 2))}
    out = {k: v.reshape(3, 1, 1).tolist() for k, v in per.items()}
    out["count"] = [int(len(frames))]
    return out


def episode_stats(table: pa.Table, images: dict[str, np.ndarray]) -> dict:
    out = {k: image_stats(v) for k, v in images.items()}
    for name in table.column_names:
        col = table.column(name)
        arr = np.array(col.to_pylist()) if pa.types.is_fixed_size_list(col.type) else col.to_numpy()
        out[name] = _stats(arr)
    return out


def aggregate_stats(per_episode: list[dict]) -> dict:
    """Dataset-wide stats (meta/stats.json) from per-episode ones: count-weighted mean, pooled std."""
    out = {}
    for key in per_episode[0] if per_episode else []:
        parts = [e[key] for e in per_episode]
        n = np.array([p["count"][0] for p in parts], dtype=np.float64)
        mean = np.array([p["mean"] for p in parts])
        var = np.array([p["std"] for p in parts]) ** 2
        w = (n / n.sum()).reshape((-1,) + (1,) * (mean.ndim - 1))
        total_mean = (w * mean).sum(0)
        total_var = (w * (var + (mean - total_mean) ** 2)).sum(0)
        out[key] = {"min": np.min([p["min"] for p in parts], axis=0).tolist(),
                    "max": np.max([p["max"] for p in parts], axis=0).tolist(),
                    "mean": total_mean.tolist(), "std": np.sqrt(total_var).tolist(), "count": [int(n.sum())]}
    return out


def _jsonl(rows: list[dict]) -> str:
    return "".join(json.dumps(r) + "\n" for r in rows)


def splits(episodes: list[dict]) -> dict[str, str]:
    """info.json's `splits`: name -> "start:end" episode range. The episodes come ordered by
    split (train first: `lerobot_export.by_split`), each split one range; an entry without a
    `split` is train. An empty split is left out (an empty dataset: train "0:0")."""
    names = [e.get("split", "train") for e in episodes]
    out, start = {}, 0
    for i in range(1, len(names) + 1):
        if i == len(names) or names[i] != names[start]:
            if names[start] in out:
                raise ValueError(f"episodes of split {names[start]!r} are not contiguous (order them by split)")
            out[names[start]] = f"{start}:{i}"
            start = i
    return out or {"train": "0:0"}


def write_meta(root: Path, episodes: list[dict], tasks: list[str], size: int, robot_type: str = "panda") -> None:
    """`episodes`: dicts with episode_index, tasks, length, stats (sorted by index) and optional
    `meta` (extra episodes.jsonl fields, e.g. a recovery demo's scene id; LeRobot's converter
    carries them into its episodes table)."""
    total_frames = sum(e["length"] for e in episodes)
    info = {
        "codebase_version": CODEBASE_VERSION, "robot_type": robot_type,
        "total_episodes": len(episodes), "total_frames": total_frames, "total_tasks": len(tasks),
        "total_videos": len(episodes) * len(VIDEO_KEYS),
        "total_chunks": (max((e["episode_index"] for e in episodes), default=-1) // CHUNKS_SIZE) + 1,
        "chunks_size": CHUNKS_SIZE, "fps": FPS, "splits": splits(episodes),
        "data_path": DATA_PATH, "video_path": VIDEO_PATH, "features": features(size),
    }
    write_text(root / "meta" / "info.json", json.dumps(info, indent=4) + "\n")
    write_text(root / "meta" / "tasks.jsonl", _jsonl([{"task_index": i, "task": t} for i, t in enumerate(tasks)]))
    write_text(root / "meta" / "episodes.jsonl", _jsonl(
        [{"episode_index": e["episode_index"], "tasks": e["tasks"], "length": e["length"], **e.get("meta", {})}
         for e in episodes]))
    write_text(root / "meta" / "stats.json", json.dumps(aggregate_stats([e["stats"] for e in episodes]), indent=4) + "\n")
    write_text(root / "meta" / "episodes_stats.jsonl", _jsonl(
        [{"episode_index": e["episode_index"], "stats": e["stats"]} for e in episodes]))
