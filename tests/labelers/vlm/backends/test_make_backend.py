"""The backend factory builds model backends and refuses everything else before any work."""

from __future__ import annotations

import pytest

from pipeline.config import VLMConfig
from pipeline.errors import ConfigError
from pipeline.labelers.vlm.backends import VLMBackend, make_backend


def test_openai_backend_is_built_with_both_prompts_in_the_configured_language():
    backend = make_backend(VLMConfig(backend="openai", language="en"))
    assert isinstance(backend, VLMBackend)
    assert {p.name for p in backend.prompts.values()} == {"localize.v2.en", "characterize.v2.en"}


def test_simstate_is_not_a_model_backend():
    with pytest.raises(ConfigError, match="simstate"):
        make_backend(VLMConfig(backend="simstate"))


def test_transformers_without_a_checkpoint_is_a_config_error():
    with pytest.raises(ConfigError, match="model_path"):
        make_backend(VLMConfig(backend="transformers"))


def test_unknown_prompt_version_fails_at_construction(tmp_path):
    with pytest.raises(ConfigError, match="prompt file not found"):
        make_backend(VLMConfig(backend="openai", prompt_version="v3", prompts_dir=tmp_path))
