"""Versioned prompt files: present in both languages, hashed, fully filled in."""

from __future__ import annotations

import hashlib

import pytest

from pipeline.errors import ConfigError
from pipeline.records import Category, Level
from pipeline.labelers.vlm.prompts import PROMPTS_DIR, load_prompt, load_prompts, prompt_text


@pytest.mark.parametrize("task", ["localize", "characterize"])
@pytest.mark.parametrize("language", ["zh", "en"])
def test_every_prompt_exists_and_its_hash_is_the_file_sha256(task, language):
    p = load_prompt(task, language)
    assert p.name == f"{task}.v1.{language}"
    assert p.sha256 == hashlib.sha256((PROMPTS_DIR / f"{p.name}.md").read_bytes()).hexdigest()
    assert "instruction" in p.fields and "duration" in p.fields


def test_chinese_is_the_default_language():
    assert load_prompt("localize").language == "zh"


def test_english_localization_prompt_follows_the_reference_text():
    p = load_prompt("localize", "en")
    assert p.template.startswith(
        "You are an expert in analyzing robot manipulation videos. Watch the entire video "
        "carefully and identify the earliest moment at which the robot experiences a "
        "task-relevant execution failure"
    )
    assert '{"fail": 2.0}' in p.template
    assert '{"fail": 2.0}' in load_prompt("localize", "zh").template


@pytest.mark.parametrize("language", ["zh", "en"])
def test_characterization_prompt_names_every_level_and_category(language):
    text = load_prompt("characterize", language).template
    assert all(f'"{lv.value}"' in text for lv in Level)
    assert all(f'"{c.value}"' in text for c in Category)
    assert "recovery_action" in text and "fail_time" in load_prompt("characterize", language).fields


def test_prompt_text_fills_every_field():
    prompts = load_prompts("en")
    text = prompt_text(prompts["characterize"], " pick up the mug ", 26.0, 3.25)
    assert '"pick up the mug"' in text and "26.0 seconds" in text and "3.2 seconds" in text and "{{" not in text


def test_render_refuses_missing_and_unknown_fields():
    p = load_prompt("localize", "en")
    with pytest.raises(ValueError, match=r"missing fields \['duration'\]"):
        p.render(instruction="x")
    with pytest.raises(ValueError, match=r"unknown fields \['colour'\]"):
        p.render(instruction="x", duration="1.0", colour="red")


def test_characterization_without_a_failure_time_is_refused():
    with pytest.raises(ValueError, match="failure time"):
        prompt_text(load_prompt("characterize", "en"), "x", 5.0)


def test_missing_prompt_version_is_a_config_error_naming_the_file():
    with pytest.raises(ConfigError, match=r"localize\.v9\.en\.md"):
        load_prompt("localize", "en", version="v9")
    with pytest.raises(ConfigError, match="language"):
        load_prompt("localize", "fr")
