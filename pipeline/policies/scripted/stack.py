"""Is the hand carrying an object, alone or as the bottom of a stack?

A stack of nested bowls is carried as one: the fingers close on the rims, and the contact
list may name the top bowl as what the hand holds. Without this, a planner that asked for
the bottom bowl would see "holding the wrong object" and put the whole stack aside.
`carried` is true when the hand holds `obj`, or holds an object resting on `obj` while
`obj` itself touches nothing else (it hangs in the air under it). `held` is what the
caller counts as held (default `Scene.holding_any`; the recovery expert passes its
stricter finger-contact reading).
"""

from __future__ import annotations

from pipeline.policies.scripted.scene import Scene

_UNSET = object()


def carried(scene: Scene, obj: str, held=_UNSET) -> bool:
    if held is _UNSET:
        held = scene.holding_any()
    if held is None:
        return False
    if held == obj:
        return True
    touching = {b if a == obj else a for a, b in scene.env.contacts() if obj in (a, b)}
    return held in touching and touching <= {held, "robot"}
