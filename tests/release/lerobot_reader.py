"""Open one of our LeRobot v2.1 exports with LeRobot's own code; print a JSON summary.

Runs under the separate reader environment (`.venv-lerobot`, built by
`scripts/setup_lerobot_reader.sh`), never the project's: `lerobot-dataset` (the standalone
`LeRobotDataset` of lerobot 0.4.4) needs numpy 2 and its own torch stack.
Usage: `python lerobot_reader.py V21_DATASET WORK_DIR [INDEX ...]`.
Steps: copy the dataset into WORK_DIR (the converter rewrites in place), convert it with
LeRobot's v2.1 -> v3.0 converter (current LeRobot refuses v2.1 and names this converter),
open it with `LeRobotDataset` from the local root (no hub: HF_HUB_OFFLINE=1), and read the
frames at INDEX (global frame indices) through LeRobot's `__getitem__`, videos included.
Output (stdout, one JSON object): what LeRobot reports about the dataset and each frame.

One piece is not LeRobot's: torchvision 0.28 (the only build for the local CPU torch) dropped
`torchvision.io.VideoReader`, which LeRobot's "pyav" video backend calls, and the PyPI
torchcodec wheels (its other backend) are CUDA-linked. We supply a small PyAV-backed
VideoReader with the old interface; LeRobot's own code still picks the frame nearest each
timestamp and asserts it lies within its tolerance.
"""

from __future__ import annotations

import base64
import contextlib
import json
import shutil
import sys
from pathlib import Path

import av
import numpy as np
import torch

_OPS = None  # keep the op-schema library alive while torchvision is loaded


def load_torchvision() -> None:
    """The PyPI torchvision 0.28 wheel is CUDA-linked; declare the two op schemas its import
    looks up so it loads on CPU torch (same fix as `pipeline.labelers.vlm.torch_compat`)."""
    global _OPS
    try:
        torch._C._dispatch_find_schema_or_throw("torchvision::nms", "")
    except RuntimeError:
        _OPS = torch.library.Library("torchvision", "FRAGMENT")
        _OPS.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        _OPS.define("qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
    import torchvision

    if not hasattr(torchvision.io, "VideoReader"):
        torchvision.io.VideoReader = PyAVVideoReader


class PyAVVideoReader:
    """The slice of torchvision's old VideoReader (pyav backend) that LeRobot uses."""

    def __init__(self, path: str, stream: str = "video") -> None:
        self.container = av.open(path)
        self._stream = self.container.streams.video[0]

    def seek(self, seconds: float, keyframes_only: bool = False) -> PyAVVideoReader:
        # backward=True lands on the key frame at or before `seconds`, as torchvision did
        self.container.seek(int(seconds / self._stream.time_base), stream=self._stream, backward=True,
                            any_frame=not keyframes_only)
        return self

    def __iter__(self):
        for frame in self.container.decode(self._stream):
            data = torch.from_numpy(frame.to_ndarray(format="rgb24")).permute(2, 0, 1)
            yield {"data": data, "pts": float(frame.pts * self._stream.time_base)}


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
    load_torchvision()
    from ledataset.datasets.lerobot_dataset import CODEBASE_VERSION, LeRobotDataset
    from ledataset.datasets.v30.convert_dataset_v21_to_v30 import convert_dataset

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
