"""Makes the PyPI torchvision 0.28 usable beside the local CPU torch, in the LeRobot environment.

Installed by `scripts/setup_lerobot.sh` into `.venv-lerobot` (as `libero_recover_lerobot_compat`,
with a `.pth` line calling `install()` at interpreter start), so LeRobot's own entry points
(`lerobot-train`, the PolicyServer, the v2.1 -> v3.0 converter) run unchanged. Two gaps:
- the PyPI torchvision wheel is CUDA-linked: its C ops do not load on CPU torch, and its import
  looks up the schemas of `torchvision::nms` / `qnms`; we declare them (same fix as
  `pipeline.labelers.vlm.torch_compat`). Nothing here calls them.
- torchvision 0.28 dropped `torchvision.io.VideoReader`, which LeRobot 0.4.4's "pyav" video
  backend calls (its other backend, torchcodec, has no build for this torch); we supply the
  slice of it LeRobot uses, backed by PyAV. LeRobot's own code still picks the frame nearest
  each timestamp and checks its tolerance.
Nothing is imported at interpreter start: an import hook acts when torchvision is first imported.
Standalone: stdlib at import time; torch and PyAV only once torchvision is imported.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys

_OPS = None  # keeps the op-schema library alive while torchvision is loaded


def _declare_ops() -> None:
    global _OPS
    import torch

    try:
        torch._C._dispatch_find_schema_or_throw("torchvision::nms", "")
    except RuntimeError:
        _OPS = torch.library.Library("torchvision", "FRAGMENT")
        _OPS.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        _OPS.define("qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")


class PyAVVideoReader:
    """The slice of torchvision's old VideoReader (pyav backend) that LeRobot uses."""

    def __init__(self, path: str, stream: str = "video") -> None:
        import av

        self.container = av.open(path)
        self._stream = self.container.streams.video[0]

    def seek(self, seconds: float, keyframes_only: bool = False) -> PyAVVideoReader:
        # backward=True lands on the key frame at or before `seconds`, as torchvision did
        self.container.seek(int(seconds / self._stream.time_base), stream=self._stream, backward=True,
                            any_frame=not keyframes_only)
        return self

    def __iter__(self):
        import torch

        for frame in self.container.decode(self._stream):
            data = torch.from_numpy(frame.to_ndarray(format="rgb24")).permute(2, 0, 1)
            yield {"data": data, "pts": float(frame.pts * self._stream.time_base)}


def _patch_io(module) -> None:
    io = sys.modules.get("torchvision.io")
    if io is not None and not hasattr(io, "VideoReader"):
        io.VideoReader = PyAVVideoReader


class _Loader(importlib.abc.Loader):
    def __init__(self, inner):
        self.inner = inner

    def create_module(self, spec):
        return self.inner.create_module(spec)

    def exec_module(self, module):
        _declare_ops()
        self.inner.exec_module(module)
        _patch_io(module)


class _Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name != "torchvision":
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is not None and spec.loader is not None:
            spec.loader = _Loader(spec.loader)
        return spec


def install() -> None:
    if "torchvision" in sys.modules:  # imported before us: patch what is there
        _declare_ops()
        _patch_io(sys.modules["torchvision"])
    elif not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.insert(0, _Finder())
