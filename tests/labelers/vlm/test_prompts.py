"""Versioned prompt files: present in both languages, hashed, fully filled in."""

from __future__ import annotations

import hashlib

import pytest
from pydantic import ValidationError

from pipeline.errors import ConfigError
from pipeline.records import Category, Level
from pipeline.config import VLMConfig
from pipeline.labelers.registry import describe
from pipeline.labelers.vlm.parse import parse_characterization, parse_localization
from pipeline.labelers.vlm.prompts import PROMPTS_DIR, load_prompt, load_prompts, prompt_text
from pipeline.labelers.vlm.schemas import Quarantine


VERSIONS = ("v1", "v2")


@pytest.mark.parametrize("task", ["localize", "characterize"])
@pytest.mark.parametrize("language", ["zh", "en"])
@pytest.mark.parametrize("version", VERSIONS)
def test_every_prompt_exists_and_its_hash_is_the_file_sha256(task, language, version):
    p = load_prompt(task, language, version)
    assert p.name == f"{task}.{version}.{language}"
    assert p.sha256 == hashlib.sha256((PROMPTS_DIR / f"{p.name}.md").read_bytes()).hexdigest()
    assert "instruction" in p.fields and "duration" in p.fields


def test_v2_is_the_default_and_v1_stays_selectable():
    assert load_prompt("localize").version == "v2" and VLMConfig().prompt_version == "v2"
    assert load_prompts("en", "v1")["characterize"].name == "characterize.v1.en"


@pytest.mark.parametrize("language", ["zh", "en"])
def test_v2_follows_the_reference_json_only_and_no_onset_for_characterization(language):
    loc, char = load_prompt("localize", language, "v2"), load_prompt("characterize", language, "v2")
    for p in (loc, char):  # no invitation to reason in the answer, as v1 had
        assert "step by step" not in p.template and "逐步思考" not in p.template
        assert ("JSON object and nothing else" in p.template) if language == "en" else ("只能是一个 JSON 对象" in p.template)
    assert "fail_time" not in char.fields and "fail_time" in load_prompt("characterize", language, "v1").fields
    gripper, order = ("gripper", "order of execution") if language == "en" else ("夹爪", "执行顺序")
    assert gripper in char.template and order in char.template


@pytest.mark.parametrize("task", ["localize", "characterize"])
@pytest.mark.parametrize("language", ["zh", "en"])
@pytest.mark.parametrize("version", VERSIONS)
def test_each_prompts_own_answer_example_parses(task, language, version):
    """The example answer a prompt shows is what the parser reads, in every version."""
    text = load_prompt(task, language, version).template
    example = next(line for line in text.splitlines() if line.startswith("{"))
    got = parse_localization(example, 10.0) if task == "localize" else parse_characterization(example)
    assert not isinstance(got, Quarantine), got


def test_prompt_version_must_look_like_a_version():
    with pytest.raises(ValidationError, match="prompt_version"):
        VLMConfig(prompt_version="2")


def test_the_labeler_description_changes_with_the_prompt_version_and_text(tmp_path):
    cfg = VLMConfig(backend="openai", language="en", prompt_version="v1")
    assert describe(cfg) != describe(cfg.model_copy(update={"prompt_version": "v2"}))
    for p in PROMPTS_DIR.glob("*.v1.en.md"):
        (tmp_path / p.name).write_bytes(p.read_bytes())
    copied = cfg.model_copy(update={"prompts_dir": tmp_path})
    assert describe(copied) == describe(cfg)
    (tmp_path / "characterize.v1.en.md").write_text("edited {{instruction}} {{duration}} {{fail_time}}")
    assert describe(copied) != describe(cfg)
    assert describe(VLMConfig()) == "simstate"


def test_chinese_is_the_default_language():
    assert load_prompt("localize").language == "zh"


@pytest.mark.parametrize("version", VERSIONS)
def test_english_localization_prompt_follows_the_reference_text(version):
    p = load_prompt("localize", "en", version)
    assert p.template.startswith(
        "You are an expert in analyzing robot manipulation videos. Watch the entire video "
        "carefully and identify the earliest moment at which the robot experiences a "
        "task-relevant execution failure"
    )
    assert '{"fail": 2.0}' in p.template
    assert '{"fail": 2.0}' in load_prompt("localize", "zh", version).template


@pytest.mark.parametrize("language", ["zh", "en"])
@pytest.mark.parametrize("version", VERSIONS)
def test_characterization_prompt_names_every_level_and_category(language, version):
    text = load_prompt("characterize", language, version).template
    assert all(f'"{lv.value}"' in text for lv in Level)
    assert all(f'"{c.value}"' in text for c in Category)
    assert "recovery_action" in text


def test_prompt_text_fills_every_field():
    prompts = load_prompts("en", "v1")
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
        prompt_text(load_prompt("characterize", "en", "v1"), "x", 5.0)
    assert "{{" not in prompt_text(load_prompt("characterize", "en", "v2"), "x", 5.0)  # v2 is not told the onset


def test_missing_prompt_version_is_a_config_error_naming_the_file():
    with pytest.raises(ConfigError, match=r"localize\.v9\.en\.md"):
        load_prompt("localize", "en", version="v9")
    with pytest.raises(ConfigError, match="language"):
        load_prompt("localize", "fr")
