"""Qwen VLM access for stages 2 and 3: prompts, video input, backends, loss-free parsing.

How a stage runner uses it (the `simstate` localizer lives in pipeline/stage2, not here):

    from pipeline.labelers.vlm.backends import VLMRequest, make_backend
    from pipeline.labelers.vlm.parse import parse_localization, parse_characterization
    from pipeline.labelers.vlm.schemas import Quarantine
    from pipeline.labelers.vlm.outcome import provenance, quarantine_entry

    backend = make_backend(cfg.stage2.vlm)              # openai | transformers; ConfigError otherwise
    results = backend.run([VLMRequest(task="localize", video=mp4, instruction=ep.instruction,
                                      frames_table=frames, key=ep.key) for ...], progress=bar_update)
    for r in results:                                    # same order as the requests
        answer = parse_localization(r, r.video.duration_s if r.video else duration_s)
        if isinstance(answer, Quarantine):
            entry = quarantine_entry(r.extra["key"], "stage2", r, answer)   # -> QuarantineEntry
        else:
            t = answer.fail                              # seconds from video start, one decimal
            # frame = round(t * r.video.source_fps) -> step through stage 1's frames table
            fields = provenance(r)                       # source, model, prompt_name, prompt_hash, raw_text

Stage 3 is the same with `task="characterize"`, `fail_time_s=...` and `parse_characterization`.
`pipeline.labelers.vlm.agreement.agreement(pairs)` compares VLM and simstate onsets.

Modules: prompts (versioned files + hash), video_input (PyAV sampling with true fps/indices),
backends/ (base Protocol + VLMResult, openai_backend, transformers_backend), parse, schemas,
outcome (record fields), agreement, torch_compat (torchvision on CPU torch).
"""
