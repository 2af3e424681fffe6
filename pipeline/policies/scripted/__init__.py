"""The `scripted` failure generator: a privileged-state expert built from motion primitives.

It plans from the task's BDDL goal and the live simulator state (`obs.sim`), and its
imperfection comes from seeded noise (`ScriptedNoise`); zero noise is the clean expert.
"""

from __future__ import annotations

from pipeline.config import ScriptedPolicyConfig
from pipeline.policies.base import Policy
from pipeline.policies.scripted.policy import ScriptedPolicy


def make_scripted_policy(cfg: ScriptedPolicyConfig, name: str | None = None) -> Policy:
    return ScriptedPolicy(cfg, name)


__all__ = ["ScriptedPolicy", "make_scripted_policy"]
