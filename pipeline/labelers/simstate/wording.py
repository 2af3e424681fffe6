"""Recovery actions in words: a grammatical imperative per (level, category, task type)
that names objects as people do ("Pick the black bowl up again and put it on the plate").

Inputs: the goal's conjuncts (BDDL names), the scene's object and fixture names, the
object the failure concerns (a target, or an operated part), an obstacle (L4), and whether
that object toppled. Output: one sentence, capitalized, ending without a full stop.

Names: `COMMON` maps a BDDL kind (the instance name without its number) to what people
call it ('akita_black_bowl' -> 'black bowl', 'flat_stove' -> 'stove'); other kinds lose
their number and underscores. An object of the same kind as the one the action is about
is "the other ..." (stack the black bowl on the other black bowl). Regions read as places:
'basket_1_contain_region' -> 'in the basket', 'wooden_cabinet_1_top_region' -> 'in the
top drawer of the cabinet', 'wooden_cabinet_1_top_side' -> 'on top of the cabinet',
'desk_caddy_1_back_contain_region' -> 'in the back compartment of the caddy',
'living_room_table_plate_right_region' -> 'to the right of the plate'.

Task types: `pick_place` (the failure concerns an object the goal moves) and `articulated`
(it concerns a drawer, door or knob the goal operates). Templates, by category then
level, are in `_object_action` and `_part_action`.
"""

from __future__ import annotations

import re

from pipeline.records import Category, Level

COMMON = {
    "akita_black_bowl": "black bowl", "white_bowl": "white bowl", "plate": "plate", "flat_stove": "stove",
    "wooden_cabinet": "cabinet", "white_cabinet": "cabinet", "wooden_two_layer_shelf": "shelf",
    "wooden_tray": "tray", "desk_caddy": "caddy", "chefmate_8_frypan": "frying pan", "porcelain_mug": "white mug",
    "white_yellow_mug": "yellow and white mug", "red_coffee_mug": "red mug", "new_salad_dressing": "salad dressing",
    "glazed_rim_porcelain_ramekin": "ramekin", "cookies": "cookie box", "main_table": "table",
    "kitchen_table": "table", "living_room_table": "table", "study_table": "table", "wine_rack": "wine rack",
}
TABLES = ("main_table", "kitchen_table", "living_room_table", "study_table")
PARTS = {"top": "top drawer", "middle": "middle drawer", "bottom": "bottom drawer"}
SIDES = {"left": "to the left of", "right": "to the right of", "front": "in front of", "back": "behind"}
VERBS = {"open": "open", "close": "close", "turnon": "turn on", "turnoff": "turn off"}
TASK_TYPES = ("pick_place", "articulated")


def kind(name: str) -> str:
    """'akita_black_bowl_1' -> 'akita_black_bowl'; 'chefmate_8_frypan_1' -> 'chefmate_8_frypan'."""
    return re.sub(r"_\d+$", "", name)


def common_name(name: str) -> str:
    k = kind(name)
    return COMMON.get(k, k.replace("_", " "))


def the(name: str, about: str | None = None) -> str:
    """'the black bowl'; 'the other black bowl' when `about` is another object of its kind."""
    other = about is not None and about != name and kind(about) == kind(name)
    return f"the {'other ' if other else ''}{common_name(name)}"


def _owner(region: str, known: list[str]) -> tuple[str, str]:
    """(owner, rest): 'basket_1_contain_region' -> ('basket_1', 'contain_region')."""
    hits = [k for k in known if region == k or region.startswith(k + "_")]
    if hits:
        owner = max(hits, key=len)
        return owner, region[len(owner) + 1:]
    for t in TABLES:
        if region.startswith(t + "_"):
            return t, region[len(t) + 1:]
    return region, ""


def place(pred: str, region: str, known: list[str], about: str | None = None) -> str:
    """Where an on/in conjunct puts something: 'on the plate', 'in the top drawer of the cabinet'."""
    owner, rest = _owner(region, known)
    words = [w for w in rest.split("_") if w not in ("region", "side", "contain")]
    if kind(owner) in TABLES and len(words) >= 2 and words[-1] in SIDES:  # a spot on the table next to a thing
        return f"{SIDES[words[-1]]} the {COMMON.get('_'.join(words[:-1]), ' '.join(words[:-1]))}"
    o = the(owner, about)
    if rest.endswith("_side") and words == ["top"]:
        return f"on top of {o}"
    if words and words[0] in PARTS and rest.endswith("_region"):
        if "cabinet" in kind(owner):
            return f"in the {PARTS[words[0]]} of {o}"
        return f"under {o}" if words[0] == "bottom" else f"on {o}"
    if words and rest.endswith("contain_region"):
        return f"in the {words[0]} compartment of {o}"
    if pred == "in" or rest in ("contain_region", "heating_region"):
        return f"in {o}"
    return f"on {o}"


def part_phrase(arg: str, known: list[str]) -> str:
    """The part an open/close/turn conjunct operates: 'the top drawer of the cabinet', 'the stove'."""
    owner, rest = _owner(arg, known)
    words = [w for w in rest.split("_") if w != "region"]
    if words and words[0] in PARTS and "cabinet" in kind(owner):
        return f"the {PARTS[words[0]]} of {the(owner)}"
    return the(owner)


def _conjuncts_of(obj: str, goal: list[list[str]]) -> list[list[str]]:
    return [c for c in goal if c[0].lower() in ("on", "in") and len(c) == 3 and c[1] == obj]


def _put(obj: str, goal: list[list[str]], known: list[str]) -> str:
    """'put it on the plate' for `obj`'s own conjunct(s)."""
    places = list(dict.fromkeys(place(c[0].lower(), c[2], known, obj) for c in _conjuncts_of(obj, goal)))
    return "put it " + " and ".join(places) if places else "put it where the task asks"


def _capital(text: str) -> str:
    return text[0].upper() + text[1:]


def _object_action(level: Level, category: Category, obj: str, put: str, aside: str | None, toppled: bool) -> str:
    o = the(obj)
    if level is Level.L4 and aside:
        return f"Push {aside} aside, then grasp {o} and {put}"
    if level is Level.L3:
        if toppled:
            return f"Set {o} upright, then pick it up and {put}"
        return f"Pick {o} up from where it landed and {put}"
    if category is Category.grasp_failure:
        return f"Grasp {o} again and {put}" if level is Level.L1 else f"Pick {o} up again and {put}"
    if category is Category.placement_failure:
        return f"Pick {o} up again and {put}, lowering it before you let go"
    if category is Category.object_displacement:
        return f"Grasp {o} where it now stands and {put}"
    if category is Category.collision_or_interaction_failure:
        return f"Approach {o} from a clear side, then grasp it and {put}"
    if category is Category.environmental_obstruction:
        return f"Move the hand clear of the obstruction, then grasp {o} and {put}"
    return f"Grasp {o} again and {put}"


def _part_action(level: Level, category: Category, verb: str, part: str, aside: str | None) -> str:
    if level is Level.L4 and aside:
        return f"Push {aside} aside, then {verb} {part}"
    if level is Level.L3:
        return f"Put back what was knocked over, then {verb} {part}"
    if category is Category.collision_or_interaction_failure and level is Level.L2:
        return f"Take a firmer hold and {verb} {part} again"
    if category is Category.environmental_obstruction:
        return f"Move the hand clear of the obstruction, then {verb} {part}"
    return f"{_capital(verb)} {part} again"


def recovery_action(level: Level, category: Category, goal: list[list[str]], objects: list[str],
                    fixtures: list[str], about: str | None = None, obstacle: str | None = None,
                    toppled: bool = False) -> str:
    """The recovery action for a failure concerning `about` (an object the goal moves, or
    an operated part; None: the goal's first conjunct)."""
    known = list(objects) + list(fixtures)
    moved = [c[1] for c in goal if c[0].lower() in ("on", "in") and len(c) == 3]
    operated = [c for c in goal if c[0].lower() in VERBS]
    owners = [_owner(c[1], known)[0] for c in operated]
    if about not in moved and about not in owners and goal:  # not what the goal is about: its first conjunct
        first = goal[0]
        about = first[1] if first[1] in moved else _owner(first[1], known)[0]
    aside = the(obstacle, about) if obstacle and obstacle != about else None
    if about in moved:
        text = _object_action(level, category, about, _put(about, goal, known), aside, toppled)
    elif operated:
        c = next((c for c, o in zip(operated, owners) if o == about), operated[0])
        text = _part_action(level, category, VERBS[c[0].lower()], part_phrase(c[1], known), aside)
    else:
        text = "Try the task again"
    return text[:200]
