"""Is the hand carrying an object, alone or as the bottom of a stack?

A stack of nested bowls is carried as one: the fingers close on the rims, and the contact
list may name the top bowl (or both) as what the hand touches. Without this, a planner
that asked for the bottom bowl would see "holding the wrong object" and put the whole
stack aside. `carried` is true when the hand touches `obj`, or touches an object resting
on `obj` while `obj` itself touches nothing else (it hangs in the air under it).
"""

from __future__ import annotations

from pipeline.policies.scripted.scene import Scene


def carried(scene: Scene, obj: str) -> bool:
    if scene.holding(obj):
        return True
    held = scene.holding_any()
    if held is None:
        return False
    touching = {b if a == obj else a for a, b in scene.env.contacts() if obj in (a, b)}
    return held in touching and touching <= {held, "robot"}
