"""The scripted expert's layers import one way: parsed with `ast` (imports inside functions
count too), no module imports one of a higher layer, the import graph has no cycle, and no
module reaches into another's private names. No simulator: these read source files."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "pipeline" / "policies"

# lowest first; a module may import its own layer (without cycles) and the layers below
LAYERS: dict[str, int] = {}
for layer, names in enumerate([
    # facts: the scene read from the simulator, the hand's primitives, noise, the record
    ["base", "scripted.scene", "scripted.primitives", "scripted.noise", "scripted.truth", "scripted.goal",
     "scripted.notes", "scripted.reach"],
    # geometry: numbers in, numbers out (some read the live scene through `Scene`)
    ["scripted.hand", "scripted.grasps", "scripted.pan_handle", "scripted.placement", "scripted.stack"],
    # motion: Ctx and the hand's moves every skill is built from
    ["scripted.motion"],
    # strategies and skills: one way each of placing, grasping, operating a part
    ["scripted.shelf", "scripted.slot", "scripted.tip_push", "scripted.slide_in", "scripted.lay_down",
     "scripted.strategies", "scripted.skills", "scripted.articulated", "scripted.drawer_room", "scripted.knobs",
     "scripted.insert"],
    # the plain expert
    ["scripted.planner", "scripted.policy", "scripted"],
    # the recovery expert: its checks and skills, its rule table, its policy
    ["scripted.recovery.reasons", "scripted.recovery.variation", "scripted.recovery.checks",
     "scripted.recovery.back_out", "scripted.recovery.unwind", "scripted.recovery.long_grasp",
     "scripted.recovery.nudge", "scripted.recovery.lying_cup", "scripted.recovery.near_grasp",
     "scripted.recovery.stand_book", "scripted.recovery.face_book", "scripted.recovery.tip_book",
     "scripted.recovery.low_drawer", "scripted.recovery.press_flat",
     "scripted.recovery.operate",
     "scripted.recovery.put_aside",
     "scripted.recovery.under_drawer", "scripted.recovery.pick_place", "scripted.recovery.rules",
     "scripted.recovery.planner", "scripted.recovery.expert", "scripted.recovery"],
    # the other failure generators (and LeRobot's training beside its policy) and the factory
    ["openpi_policy", "lerobot_policy", "lerobot_train", "factory", ""],
]):
    for n in names:
        LAYERS[n] = layer


def module_name(path: Path) -> str:
    rel = path.relative_to(PKG).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


MODULES = {module_name(p): p for p in PKG.rglob("*.py")}


def _local(dotted: str) -> str | None:
    """The module of pipeline.policies that a dotted import names, or None."""
    if dotted != "pipeline.policies" and not dotted.startswith("pipeline.policies."):
        return None
    mod = dotted.removeprefix("pipeline.policies").lstrip(".")
    return mod if mod in MODULES else None


def imports(name: str) -> set[str]:
    """Modules of pipeline.policies that `name` imports anywhere in its source."""
    out = set()
    for node in ast.walk(ast.parse(MODULES[name].read_text())):
        if isinstance(node, ast.Import):
            out |= {_local(a.name) for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            # `from pkg import mod` imports the submodule when there is one, else a name of pkg
            out |= {_local(f"{node.module}.{a.name}") or _local(node.module) for a in node.names}
    return out - {None, name}


GRAPH = {m: imports(m) for m in MODULES}


def test_every_module_has_a_layer():
    assert sorted(set(MODULES) - set(LAYERS)) == []


def test_a_module_imports_only_its_own_layer_and_below():
    upward = [f"{n} (layer {LAYERS[n]}) imports {m} (layer {LAYERS[m]})"
              for n in sorted(MODULES) for m in sorted(GRAPH[n]) if LAYERS[m] > LAYERS[n]]
    assert upward == [], "a higher layer: " + "; ".join(upward)


def test_the_import_graph_has_no_cycle():
    state: dict[str, int] = {}  # 1: on the path, 2: done

    def visit(m: str, path: list[str]) -> list[str] | None:
        state[m] = 1
        for n in sorted(GRAPH[m]):
            if state.get(n) == 1:
                return path + [m, n]
            if n not in state and (cycle := visit(n, path + [m])):
                return cycle
        state[m] = 2
        return None

    for m in sorted(MODULES):
        if m not in state:
            cycle = visit(m, [])
            assert cycle is None, " -> ".join(cycle)


def test_the_plain_expert_never_reaches_the_recovery_layer():
    plain = [m for m in MODULES if m.startswith("scripted") and not m.startswith("scripted.recovery")]
    seen, todo = set(), list(plain)
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo.extend(GRAPH[m])
    assert sorted(m for m in seen if m.startswith("scripted.recovery")) == []


def test_no_module_uses_another_modules_private_names():
    found = []
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pipeline"):
                found += [f"{name}: from {node.module} import {a.name}" for a in node.names
                          if a.name.startswith("_") and not a.name.startswith("__")]
            elif (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                  and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))):
                found.append(f"{name}:{node.lineno}: .{node.attr}")
    assert found == []


def test_the_checker_sees_a_cycle_and_an_upward_import():
    # the two checks above are only worth something if they can fail
    before = {m: set(v) for m, v in GRAPH.items()}
    try:
        GRAPH["scripted.placement"].add("scripted.skills")
        with pytest.raises(AssertionError, match="higher layer"):
            test_a_module_imports_only_its_own_layer_and_below()
        with pytest.raises(AssertionError, match="placement"):
            test_the_import_graph_has_no_cycle()
    finally:
        GRAPH.clear()
        GRAPH.update(before)
