"""VLM backends behind one Protocol (`base.VLMBackend`), chosen by `VLMConfig.backend`.

`make_backend(vlm_cfg)` builds `openai` or `transformers` with both prompts loaded (so a
missing prompt file fails before any work). `simstate` needs no model and is built by
`pipeline.labelers.registry`; asking this factory for it is a ConfigError.
"""

from __future__ import annotations

from pipeline.config import VLMConfig
from pipeline.errors import ConfigError
from pipeline.labelers.vlm.backends.base import VideoSent, VLMBackend, VLMRequest, VLMResult
from pipeline.labelers.vlm.prompts import load_prompts

__all__ = ["VLMBackend", "VLMRequest", "VLMResult", "VideoSent", "make_backend"]


def make_backend(cfg: VLMConfig, **kwargs) -> VLMBackend:
    """The configured model backend; `kwargs` go to its constructor (e.g. logits_processors)."""
    if cfg.backend not in ("openai", "transformers"):
        raise ConfigError(
            f"vlm.backend: {cfg.backend!r} is not a model backend (openai | transformers); "
            "'simstate' is built by pipeline.labelers.registry"
        )
    prompts = load_prompts(cfg.language, cfg.prompt_version, cfg.prompts_dir)
    if cfg.backend == "openai":
        from pipeline.labelers.vlm.backends.openai_backend import OpenAIBackend

        return OpenAIBackend(cfg.openai, cfg.sampling, prompts, **kwargs)
    from pipeline.labelers.vlm.backends.transformers_backend import TransformersBackend

    return TransformersBackend(cfg.transformers, cfg.sampling, prompts, **kwargs)
