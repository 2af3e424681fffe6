"""torch_compat shims torchvision only when it cannot load by itself (each case in a fresh process).

The import order is the whole bug: on a CUDA machine torchvision registers `torchvision::nms`
itself, and a shim defined before that import aborted the process. A stand-in torchvision
package that registers the op at import, as a CUDA build's C++ extension does, reproduces that
order on CPU.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

if importlib.util.find_spec("torch") is None or importlib.util.find_spec("torchvision") is None:
    pytest.skip("the `vlm` extra (torch, torchvision) is not installed", allow_module_level=True)

ROOT = Path(__file__).resolve().parents[2]


def _python(code: str, extra_path: Path | None = None) -> subprocess.CompletedProcess:
    path = [str(p) for p in (extra_path, ROOT) if p is not None]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(path + [os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                          timeout=300)


def test_a_torchvision_that_registers_its_own_ops_is_imported_untouched(tmp_path):
    fake = tmp_path / "torchvision"
    fake.mkdir()
    (fake / "__init__.py").write_text(textwrap.dedent("""
        # what a CUDA build does at import: its C++ extension defines the operators
        import torch
        _lib = torch.library.Library("torchvision", "DEF")
        _lib.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        _lib.define("qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        STAND_IN = True
    """))
    out = _python("""
        from pipeline.labelers.vlm import torch_compat
        torch_compat.ensure_torchvision()
        import torchvision
        assert torchvision.STAND_IN and not torch_compat.shimmed()
        torch_compat.ensure_torchvision()  # idempotent
        print("loaded-without-shim")
    """, extra_path=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "loaded-without-shim" in out.stdout


def test_the_installed_torchvision_is_shimmed_only_if_it_cannot_load_by_itself():
    plain = _python("import torchvision")
    out = _python("""
        from pipeline.labelers.vlm import torch_compat
        torch_compat.ensure_torchvision()
        import torchvision.transforms.v2
        from transformers import AutoVideoProcessor  # what the backend needs from it
        print("shimmed" if torch_compat.shimmed() else "not-shimmed")
    """)
    assert out.returncode == 0, out.stderr[-2000:]
    if plain.returncode == 0:  # a build whose ops load (e.g. CUDA torch + torchvision)
        assert "not-shimmed" in out.stdout
    else:  # CPU torch with the CUDA-linked PyPI wheel: the landed case of this machine
        assert "operator torchvision::nms does not exist" in plain.stderr
        assert "shimmed" in out.stdout.split()
