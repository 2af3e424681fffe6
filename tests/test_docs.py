"""ARCHITECTURE.md and docs/data-format.md name only code that exists.

Every backticked name on the two pages is checked: a dotted name (`runner.Stage`,
`stage2.stage`, `pipeline.release.experts`, `arrow.arrow_schema(Model)`) must import as a
module of `pipeline` with its attributes, or be a config key (`release.lerobot_dir`); a
`.py` path must be a file (under `pipeline/` or the repository, a bare name anywhere in
`pipeline/`); a CamelCase or UPPER_CASE
name must be defined in `pipeline/`. Run paths (with `<...>`) and layout calls (`L....`)
are test_layout.py's business.
"""

from __future__ import annotations

import builtins
import enum
import importlib
import re
from pathlib import Path

import pytest

REPO = Path(__file__).parents[1]
PAGES = [REPO / "ARCHITECTURE.md", REPO / "docs" / "data-format.md"]
DOTTED = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)+$")
FILE_KINDS = {"npy", "npz", "png", "json", "jsonl", "yaml", "parquet", "md", "mp4", "txt", "done", "bddl", "sqlite"}
DEFINED = re.compile(r"^\s*(?:class|def)\s+(\w+)|^(\w+)\s*(?::[^=]*)?=", re.M)


def _names(page: Path) -> list[str]:
    out = []
    for token in re.findall(r"`([^`\n]+)`", page.read_text()):
        token = re.sub(r"\(.*\)$", "", token.strip())  # a call: its function
        if "<" in token or token.startswith("L.") or " " in token:
            continue
        out.append(token)
    return out


def _defined() -> set[str]:
    names: set[str] = set()
    for f in (REPO / "pipeline").rglob("*.py"):
        names |= {a or b for a, b in DEFINED.findall(f.read_text())}
    return names


def _config_keys() -> set[str]:
    from pydantic import BaseModel

    from pipeline.config import Config

    keys: set[str] = set()

    def walk(model: type[BaseModel], prefix: str) -> None:
        for name, field in model.model_fields.items():
            keys.add(prefix + name)
            ann = field.annotation
            if isinstance(ann, type) and issubclass(ann, BaseModel):
                walk(ann, f"{prefix}{name}.")

    walk(Config, "")
    return keys


def _packages_holding(module: str) -> list[list[str]]:
    """`pipeline` and every package under it that has a module or subpackage `module`: a page
    section about one package names its modules without the package (`deps.json_body`)."""
    found = [[]]
    for f in (REPO / "pipeline").rglob(f"{module}*"):
        if f.name == f"{module}.py" or (f.is_dir() and (f / "__init__.py").is_file() and f.name == module):
            pkg = list(f.relative_to(REPO / "pipeline").parent.parts)
            if pkg and pkg not in found:
                found.append(pkg)
    return found


def _resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    if parts[0] == "pipeline":
        parts = parts[1:]
    return any(_resolves_in(pkg, parts) for pkg in _packages_holding(parts[0]))


def _resolves_in(pkg: list[str], parts: list[str]) -> bool:
    for i in range(len(parts), 0, -1):  # the longest module prefix, then attributes
        try:
            obj = importlib.import_module(".".join(["pipeline", *pkg, *parts[:i]]))
        except ImportError:
            continue
        for attr in parts[i:]:
            fields = getattr(obj, "model_fields", None) or getattr(obj, "__dataclass_fields__", None) or {}
            if not hasattr(obj, attr) and attr not in fields:
                return False
            obj = getattr(obj, attr, None)
        return True
    return False


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_module_function_and_class_a_doc_page_names_exists(page):
    defined, keys = _defined(), _config_keys()
    missing = []
    for name in _names(page):
        if name.endswith(".py"):  # a bare file name is one in the package its table row is about
            ok = (REPO / "pipeline" / name).is_file() or (REPO / name).is_file() or \
                ("/" not in name and any((REPO / "pipeline").rglob(name)))
        elif name.rsplit(".", 1)[-1] in FILE_KINDS:
            continue  # a file of a run
        elif DOTTED.match(name):
            head = name.split(".")[0]
            ok = (_resolves(name) or any(k == name or k.endswith("." + name) for k in keys)
                  or (head[0].isupper() and head in defined))  # a record's field: `EpisodeRecord.path`
        elif re.fullmatch(r"[A-Z][A-Za-z0-9_]*", name):
            ok = name in defined or hasattr(builtins, name) or hasattr(enum, name)
        else:
            continue  # a word, a value, a run path: not code
        if not ok:
            missing.append(name)
    assert not missing, f"{page.name} names code that does not exist: {sorted(set(missing))}"


def test_the_check_sees_a_name_that_is_gone():
    assert not _resolves("stage2.worker") and _resolves("stage2.stage") and _resolves("runner.Stage")
    assert not _resolves("release.certify.certify_everything") and _resolves("release.certify.CertifyStage")
    assert _resolves("deps.json_body") and not _resolves("deps.no_such_function")
