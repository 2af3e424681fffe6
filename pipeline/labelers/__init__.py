"""Labelers: what proposes a failure's onset (localizers, stage 2) and its level, category and
recovery action (characterizers, stage 3). Two families behind one pair of protocols
(`base.Localizer`, `base.Characterizer`), chosen by the config's backend name (`registry`):

- `simstate/`: rules over the simulator evidence, no model (events, localizer, characterizer);
- `vlm/`: a Qwen VLM behind the `openai` or `transformers` backend (prompts, parser).
"""
