"""Make `torchvision` importable on CPU-only torch, in one place, and only where needed.

transformers' video processors import torchvision. Two installs meet this module:
- A torchvision whose C++ ops load (CUDA torch + CUDA torchvision on a GPU machine): it
  registers `torchvision::nms` itself. Defining that schema before it would make its import
  abort the whole process (`c10::Error ... registered multiple times`, exit 134), so it is
  imported first, untouched.
- The PyPI torchvision 0.28.0 wheel with CPU torch 2.13.0: its C++ ops never register and
  the import raises `operator torchvision::nms does not exist`. Only then are the two op
  schemas it looks up (nms, qnms) declared and the import retried; we never call them.

Call `ensure_torchvision()` before importing transformers' vision code. Idempotent.
"""

from __future__ import annotations

import importlib.util
import sys

_LIB = None  # keep the Library alive: dropping it would unregister the schemas
_MISSING_OPS = "torchvision::nms"  # the import error of a torchvision whose C++ ops did not load


def shimmed() -> bool:
    """Whether this process needed the CPU schema shim."""
    return _LIB is not None


def ensure_torchvision() -> None:
    global _LIB
    if _LIB is not None or importlib.util.find_spec("torchvision") is None:
        return  # done already, or transformers will report the missing package itself
    try:
        import torchvision  # noqa: F401
        return  # it loads by itself (its ops registered): never shim
    except RuntimeError as e:
        if _MISSING_OPS not in str(e):
            raise
    # the failed import left half-initialized submodules behind; retry from scratch
    for name in [m for m in sys.modules if m == "torchvision" or m.startswith("torchvision.")]:
        del sys.modules[name]
    import torch

    lib = torch.library.Library("torchvision", "FRAGMENT")
    lib.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
    lib.define("qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
    _LIB = lib
    import torchvision  # noqa: F401,F811  (import now, while the schemas are in place)
