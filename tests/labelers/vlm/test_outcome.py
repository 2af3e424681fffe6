"""Backend results become record fields and quarantine entries without losing the raw output."""

from __future__ import annotations

from pipeline.records import QuarantineEntry
from pipeline.labelers.vlm.backends.base import VLMResult
from pipeline.labelers.vlm.outcome import provenance, quarantine_entry
from pipeline.labelers.vlm.parse import parse_localization


def _result(**kw) -> VLMResult:
    return VLMResult(
        backend="openai",
        model="Qwen/Qwen3.5-27B",
        task="localize",
        prompt_name="localize.v1.zh",
        prompt_hash="ab" * 32,
        **kw,
    )


def test_quarantine_entry_carries_reason_prompt_and_full_raw_output():
    r = _result(content=None, reasoning="thinking about 2.0 s", finish_reason="length")
    entry = quarantine_entry("libero_goal/task/ep", "stage2", r, parse_localization(r, 10.0))
    assert isinstance(entry, QuarantineEntry)
    assert entry.reason == "truncated" and entry.source == "openai" and entry.prompt_name == "localize.v1.zh"
    assert "thinking about 2.0 s" in entry.raw_text and entry.model == "Qwen/Qwen3.5-27B"


def test_provenance_keeps_thinking_and_answer_together():
    fields = provenance(_result(content='{"fail": 1.0}', reasoning="why"))
    assert fields["raw_text"] == '<think>\nwhy\n</think>\n{"fail": 1.0}' and fields["prompt_hash"] == "ab" * 32
