"""Qwen VLM access for stages 2 and 3: prompts, video input, backends, loss-free parsing.

How a stage uses it (through the labeler protocols of `pipeline.labelers.base`):

    from pipeline.labelers.base import Episode
    from pipeline.labelers.registry import make_characterizer, make_localizer

    localizer = make_localizer(cfg.stage2.vlm)          # openai | transformers (| simstate)
    onsets = localizer.localize([Episode(rec, folder, video, frames) for ...], progress=tick)
    for onset in onsets:                                 # same order as the episodes
        if onset.found:
            t = onset.fail_time_s                        # seconds from video start, one decimal
            # step = step_for_time(t, frames, rec.steps) -> stage 1's frames table
        else:
            onset.reason, onset.detail                   # no_video, backend_error, truncated, no_json, ...
        onset.trace()                                    # model, prompt_name, prompt_hash, raw_text
    localizer.close()

Stage 3 is the same with `make_characterizer(cfg.stage3.vlm, run_dir).characterize(localizations)`.
`pipeline.labelers.vlm.agreement.agreement(pairs)` compares VLM and simstate onsets.

Modules: labeler (VLMLocalizer, VLMCharacterizer), prompts (versioned files + hash),
video_input (PyAV sampling with true fps/indices), backends/ (base Protocol + VLMResult,
openai_backend, transformers_backend), parse, schemas, agreement, torch_compat (torchvision
on CPU torch).
"""
