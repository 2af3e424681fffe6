"""The placement strategies, in the order `skills.place` asks them.

A strategy is a module with `applies(ctx, obj, target)` (None: not this one; anything
else: how, handed to `plan`) and `plan(ctx, obj, target, how)` (the primitives). The
first that applies takes the object in its own way; when none does, `place` puts it down
at `placement.place_choice`'s spot. A new way of putting things somewhere is a new module
here plus one entry in `PLACEMENTS` (see docs/adding-a-skill.md). Evaluated in order and
lazily: an earlier strategy's `applies` runs first, as the plans were tuned with.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pipeline.policies.scripted import lay_down, shelf, slide_in, slot, tip_push
from pipeline.policies.scripted.motion import Ctx, Plan


@dataclass(frozen=True)
class Placement:
    name: str
    applies: Callable[[Ctx, str, str], Any]
    plan: Callable[[Ctx, str, str, Any], Plan]


PLACEMENTS: tuple[Placement, ...] = tuple(
    Placement(m.__name__.rsplit(".", 1)[-1], m.applies, m.plan)
    # a book into a roofed shelf, or tipped in under a low one, or into a narrow compartment;
    # a pan into a shelf compartment by its handle; a tall object laid in a shallow drawer
    for m in (shelf, tip_push, slot, slide_in, lay_down)
)


def placement_for(ctx: Ctx, obj: str, target: str, before: Callable | None = None) -> tuple[Placement, Any] | None:
    """The first strategy that takes `obj` to `target` its own way, with its `applies`
    answer, or None; `before`: only among the strategies ahead of the one whose plan it is."""
    for strategy in PLACEMENTS:
        if strategy.plan is before:
            return None
        how = strategy.applies(ctx, obj, target)
        if how is not None:
            return strategy, how
    return None
