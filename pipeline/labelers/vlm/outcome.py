"""Turn a backend result + parser verdict into the fields of the stage records.

`provenance(result)` gives the model / prompt name / prompt hash / raw text that every
`Localization` or `Characterization` record carries; `quarantine_entry(...)` builds the
`QuarantineEntry` for an unusable answer, with its reason and the full raw output.
"""

from __future__ import annotations

from pipeline.records import QuarantineEntry
from pipeline.labelers.vlm.backends.base import VLMResult
from pipeline.labelers.vlm.schemas import Quarantine


def provenance(result: VLMResult) -> dict:
    return {
        "source": result.backend,
        "model": result.model,
        "prompt_name": result.prompt_name,
        "prompt_hash": result.prompt_hash,
        "raw_text": result.raw_text,
    }


def quarantine_entry(key: str, stage: str, result: VLMResult, quarantine: Quarantine) -> QuarantineEntry:
    return QuarantineEntry(
        key=key,
        stage=stage,
        reason=quarantine.reason.value,
        detail=quarantine.detail,
        **{**provenance(result), "raw_text": quarantine.raw_text or result.raw_text or None},
    )
