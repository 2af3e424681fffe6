"""Make `torchvision` importable on CPU-only torch, in one place.

transformers' video processors import torchvision. The PyPI torchvision 0.28.0 wheel is
CUDA-linked; with CPU torch 2.13.0 its C++ ops never register, and its fake-tensor
registrations then fail with `operator torchvision::nms does not exist`. Declaring the two op
schemas it looks up (nms, qnms) before the first import lets it load; we never call them.

Call `ensure_torchvision()` before importing transformers' vision code. Idempotent.
"""

from __future__ import annotations

import importlib.util
import sys

_LIB = None  # keep the Library alive: dropping it would unregister the schemas


def ensure_torchvision() -> None:
    global _LIB
    if "torchvision" in sys.modules or _LIB is not None:
        return
    if importlib.util.find_spec("torchvision") is None:
        return  # transformers will report the missing package itself
    import torch

    try:
        torch._C._dispatch_find_schema_or_throw("torchvision::nms", "")
        return  # a working torchvision build already registered its ops
    except RuntimeError:
        pass
    lib = torch.library.Library("torchvision", "FRAGMENT")
    lib.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
    lib.define("qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
    _LIB = lib
    import torchvision  # noqa: F401  (import now, while the schemas are in place)
