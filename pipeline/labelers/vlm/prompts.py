"""Versioned prompt files, loaded by task + language, hashed, and filled in.

Input: `prompts/<task>.<version>.<language>.md` (UTF-8), e.g. `localize.v2.zh.md`, with
`{{placeholder}}` fields (`instruction`, `duration`, and for v1's characterization `fail_time`).
Versions: `v1` (the answer may follow step-by-step reasoning; characterization is told the
onset) and `v2`, the default (the reference's requirements: the answer is the JSON object
only, reasoning belongs before it or in the model's reasoning channel; characterization is
not told the onset and covers the gripper's state and the order of execution). Both give
the same JSON keys, so one parser reads either.
Output: a `Prompt` whose `name` ("localize.v1.zh") and `sha256` (of the file's bytes) are
recorded with every annotation it produces, and whose `render(**fields)` fills every field.

Invariants: a prompt file is never edited in place once results exist: a change is a new
version file, so (name, sha256) always identifies the exact text a model saw. `render`
refuses a missing or an unknown field (a prompt silently sent with `{{instruction}}` in it
would still get answers, just wrong ones).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import ConfigError

PROMPTS_DIR = Path(__file__).resolve().parents[3] / "prompts"
TASKS = ("localize", "characterize")
LANGUAGES = ("zh", "en")
DEFAULT_VERSION = "v2"
_FIELD = re.compile(r"\{\{\s*([a-z_]+)\s*\}\}")


@dataclass(frozen=True)
class Prompt:
    name: str  # "<task>.<version>.<language>", the file stem
    task: str
    version: str
    language: str
    template: str
    sha256: str
    path: Path

    @property
    def fields(self) -> set[str]:
        return set(_FIELD.findall(self.template))

    def render(self, **values: object) -> str:
        missing = self.fields - values.keys()
        unknown = values.keys() - self.fields
        if missing or unknown:
            raise ValueError(f"prompt {self.name}: missing fields {sorted(missing)}, unknown fields {sorted(unknown)}")
        return _FIELD.sub(lambda m: str(values[m.group(1)]), self.template)


def load_prompt(
    task: str, language: str = "zh", version: str = DEFAULT_VERSION, directory: str | Path | None = None
) -> Prompt:
    """Load `<directory>/<task>.<version>.<language>.md`; ConfigError names the file if absent."""
    if task not in TASKS:
        raise ConfigError(f"unknown prompt task {task!r}; choose from {list(TASKS)}")
    if language not in LANGUAGES:
        raise ConfigError(f"unknown prompt language {language!r}; choose from {list(LANGUAGES)}")
    name = f"{task}.{version}.{language}"
    path = Path(directory or PROMPTS_DIR) / f"{name}.md"
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(
            f"{path}: prompt file not found (task={task}, version={version}, language={language})"
        ) from None
    return Prompt(
        name=name,
        task=task,
        version=version,
        language=language,
        template=data.decode("utf-8"),
        sha256=hashlib.sha256(data).hexdigest(),
        path=path,
    )


def format_seconds(t: float) -> str:
    """Times in prompts use one decimal, like the answers we ask for."""
    return f"{t:.1f}"


def load_prompts(
    language: str = "zh", version: str = DEFAULT_VERSION, directory: str | Path | None = None
) -> dict[str, Prompt]:
    """Both tasks' prompts, keyed by task; fails at startup, not mid-run, if one is missing."""
    return {task: load_prompt(task, language, version, directory) for task in TASKS}


def prompt_text(prompt: Prompt, instruction: str, duration_s: float, fail_time_s: float | None = None) -> str:
    """Fill a localize/characterize prompt for one video."""
    values: dict[str, object] = {"instruction": instruction.strip(), "duration": format_seconds(duration_s)}
    if "fail_time" in prompt.fields:
        if fail_time_s is None:
            raise ValueError(f"prompt {prompt.name} needs the failure time")
        values["fail_time"] = format_seconds(fail_time_s)
    return prompt.render(**values)


def prompts_digest(language: str = "zh", version: str = DEFAULT_VERSION, directory: str | Path | None = None) -> str:
    """Short id of the exact prompt texts a run sends (both tasks' names and SHA-256): part of
    every fingerprint that must redo model answers when the prompt changes."""
    prompts = load_prompts(language, version, directory)
    blob = "\n".join(f"{p.name}:{p.sha256}" for _, p in sorted(prompts.items()))
    return hashlib.sha256(blob.encode()).hexdigest()[:16]
