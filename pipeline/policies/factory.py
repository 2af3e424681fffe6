"""Build the configured policy: `make_policy(PolicyConfig) -> Policy`.

Imports each policy kind lazily, so a state-only run never loads the openpi client and an
openpi run never loads the scripted planner; `lerobot` is a LeRobot checkpoint behind
LeRobot's PolicyServer (lerobot_policy.py). `recovery` is the zero-noise recovery
expert (a reference policy for `recover eval`; stage 1 generates failures with `scripted`).
"""

from __future__ import annotations

from pipeline.config import PolicyConfig
from pipeline.errors import ConfigError
from pipeline.policies.base import Policy


def make_policy(cfg: PolicyConfig) -> Policy:
    if cfg.kind == "scripted":
        from pipeline.policies.scripted import make_scripted_policy

        return make_scripted_policy(cfg.scripted, name=cfg.name)
    if cfg.kind == "recovery":
        from pipeline.policies.scripted.recovery import RecoveryExpert

        return RecoveryExpert(variation=0.0, name=cfg.name or "recovery")
    if cfg.kind == "openpi":
        from pipeline.policies.openpi_policy import OpenpiPolicy

        return OpenpiPolicy(cfg.openpi, name=cfg.name)
    if cfg.kind == "lerobot":
        from pipeline.policies.lerobot_policy import LerobotPolicy

        return LerobotPolicy(cfg.lerobot, name=cfg.name)
    raise ConfigError(f"policy.kind: unknown policy kind {cfg.kind!r}")
