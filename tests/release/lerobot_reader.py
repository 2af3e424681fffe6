"""Open one of our LeRobot v2.1 exports with LeRobot's own code; print a JSON summary.

Runs under the separate reader environment (`.venv-lerobot`, built by
`scripts/setup_lerobot.sh`), never the project's: lerobot 0.4.4 needs numpy 2.
Usage: `python lerobot_reader.py V21_DATASET WORK_DIR [INDEX ...]`.
Steps: copy the dataset into WORK_DIR (the converter rewrites in place), convert it with
LeRobot's v2.1 -> v3.0 converter (current LeRobot refuses v2.1 and names this converter),
open it with `LeRobotDataset` from the local root (no hub: HF_HUB_OFFLINE=1), and read the
frames at INDEX (global frame indices) through LeRobot's `__getitem__`, videos included.
Output (stdout, one JSON object): what LeRobot reports about the dataset and each frame.

The LeRobot environment (`scripts/setup_lerobot.sh`) holds the real `lerobot` 0.4.4; its
torchvision fix (`pipeline/lerobot_env/lerobot_compat.py`, loaded at interpreter start) supplies
the PyAV VideoReader LeRobot's "pyav" backend calls.
"""

from __future__ import annotations

import base64
import contextlib
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import torch


def frame_summary(item: dict, image_keys: list[str]) -> dict:
    out = {"index": int(item["index"]), "episode_index": int(item["episode_index"]),
           "frame_index": int(item["frame_index"]), "timestamp": float(item["timestamp"]),
           "task": item["task"], "state": item["observation.state"].tolist(), "action": item["action"].tolist()}
    for key in ("observation.states.joint_state", "observation.states.gripper_state"):
        if key in item:  # the arm's joint states, as LeRobot reads them
            out[key] = item[key].tolist()
    for key in image_keys:
        img = item[key]  # float in [0, 1], channels first
        out[key] = {"shape": list(img.shape), "dtype": str(img.dtype), "mean": float(img.mean()),
                    "std": float(img.std()), "min": float(img.min()), "max": float(img.max()),
                    # the pixels back as HWC uint8, so the caller can compare them with the MP4
                    "rgb24": base64.b64encode((img.permute(1, 2, 0) * 255).round().to(torch.uint8)
                                              .numpy().tobytes()).decode()}
    return out


def main(src: Path, work: Path, indices: list[int]) -> dict:
    from lerobot.datasets.lerobot_dataset import CODEBASE_VERSION, LeRobotDataset
    from lerobot.datasets.v30.convert_dataset_v21_to_v30 import convert_dataset

    name = src.name
    shutil.copytree(src, work / name)
    convert_dataset(repo_id=name, root=work, push_to_hub=False, force_conversion=True)
    ds = LeRobotDataset(f"local/{name}", root=work / name, video_backend="pyav")
    image_keys = list(ds.meta.video_keys)
    return {
        "codebase_version": CODEBASE_VERSION,
        "converted_version": ds.meta.info["codebase_version"],
        "len": len(ds), "num_frames": ds.num_frames, "num_episodes": ds.num_episodes, "fps": ds.fps,
        "features": {k: {"dtype": v["dtype"], "shape": list(v["shape"])} for k, v in ds.features.items()},
        "video_keys": image_keys,
        "tasks": ds.meta.tasks.index.tolist(),
        "episode_lengths": [int(x) for x in np.asarray(ds.meta.episodes["length"])],
        # our extra episodes.jsonl fields (recovery demos), as LeRobot's converter carried them over
        "episode_meta": {k: list(ds.meta.episodes[k]) for k in ("scene_id", "level", "category")
                         if k in ds.meta.episodes.column_names},
        "frames": [frame_summary(ds[i], image_keys) for i in indices],
    }


if __name__ == "__main__":
    with contextlib.redirect_stdout(sys.stderr):  # the converter prints progress; stdout is ours
        summary = main(Path(sys.argv[1]), Path(sys.argv[2]), [int(i) for i in sys.argv[3:]])
    print(json.dumps(summary))
