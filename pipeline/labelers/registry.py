"""Labelers by the config's backend name: `simstate` (rules, no model) | `openai` |
`transformers` (a VLM backend). Building one checks what it needs (a prompt file, a model)
before any work; an unknown name is a ConfigError (the config schema already refuses one).
"""

from __future__ import annotations

from pathlib import Path

from pipeline.config import VLMConfig
from pipeline.errors import ConfigError
from pipeline.labelers.base import Characterizer, Localizer

BACKENDS = ("simstate", "openai", "transformers")


def describe(cfg: VLMConfig) -> str:
    """What a labeler's answers depend on: `simstate`, or backend, model, prompt version and
    language, and the prompt files' digest (so an edited prompt file also counts)."""
    if cfg.backend == "simstate":
        return "simstate"
    from pipeline.labelers.vlm.prompts import prompts_digest

    model = cfg.openai.model if cfg.backend == "openai" else str(cfg.transformers.model_path)
    digest = prompts_digest(cfg.language, cfg.prompt_version, cfg.prompts_dir)
    return f"{cfg.backend}:{model}:{cfg.prompt_version}:{cfg.language}:{digest}"


def _check(name: str) -> None:
    if name not in BACKENDS:
        raise ConfigError(f"vlm.backend: {name!r} is not a labeler; choose one of {BACKENDS}")


def make_localizer(cfg: VLMConfig, backend=None) -> Localizer:
    """`backend`: an open VLM backend to reuse (one model for localizing and characterizing)."""
    _check(cfg.backend)
    if cfg.backend == "simstate":
        from pipeline.labelers.simstate.labeler import SimstateLocalizer

        return SimstateLocalizer()
    from pipeline.labelers.vlm.labeler import VLMLocalizer

    return VLMLocalizer(cfg, backend)


def make_characterizer(cfg: VLMConfig, run_dir: Path, backend=None, evidence_for=None) -> Characterizer:
    """Characterizes the localizations of the run folder `run_dir` (its evidence and videos).
    `evidence_for(loc)`: simstate evidence measured by the caller instead of read from the run."""
    _check(cfg.backend)
    if cfg.backend == "simstate":
        from pipeline.labelers.simstate.labeler import SimstateCharacterizer

        return SimstateCharacterizer(run_dir, evidence_for)
    from pipeline.labelers.vlm.labeler import VLMCharacterizer

    return VLMCharacterizer(cfg, run_dir, backend)
