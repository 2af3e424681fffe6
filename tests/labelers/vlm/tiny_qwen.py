"""Build tiny, randomly initialized Qwen-VL checkpoints offline (test fixture factory).

Real model classes, real processors, a byte-level tokenizer carrying the Qwen special
tokens, and a minimal Qwen-style chat template: `save_pretrained` writes a folder under
1 MB that `AutoModelForImageTextToText` / `AutoProcessor` reload like a real checkpoint.
Rules that bite (see shared/notes/vlm-facts.md): vocab_size = len(tokenizer); the four
vision token ids in the config; vision out_hidden_size = text hidden_size; mrope_section
sums to head_dim * partial_rotary_factor / 2.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.labelers.vlm.torch_compat import ensure_torchvision

SPECIAL = [
    "<|endoftext|>",
    "<|im_start|>",
    "<|im_end|>",
    "<|vision_start|>",
    "<|vision_end|>",
    "<|image_pad|>",
    "<|video_pad|>",
]
THINK = ["<think>", "</think>"]  # ordinary (non-special) added tokens, as in Qwen3

# just enough of Qwen's template: system/user turns, a video placeholder, generation prompt
CHAT_TEMPLATE = (
    "{% for m in messages %}<|im_start|>{{ m['role'] }}\n"
    "{% if m['content'] is string %}{{ m['content'] }}{% else %}"
    "{% for c in m['content'] %}{% if c['type'] == 'video' %}<|vision_start|><|video_pad|><|vision_end|>"
    "{% elif c['type'] == 'text' %}{{ c['text'] }}{% endif %}{% endfor %}{% endif %}"
    "<|im_end|>\n{% endfor %}{% if add_generation_prompt %}<|im_start|>assistant\n"
    "{% if enable_thinking is defined and enable_thinking %}<think>\n{% endif %}{% endif %}"
)


def _tokenizer():
    from tokenizers import Tokenizer, decoders, models, pre_tokenizers
    from transformers import PreTrainedTokenizerFast

    alphabet = pre_tokenizers.ByteLevel.alphabet()
    vocab = {ch: i for i, ch in enumerate(sorted(alphabet))}
    tok = Tokenizer(models.BPE(vocab=vocab, merges=[]))
    tok.pre_tokenizer = pre_tokenizers.ByteLevel(add_prefix_space=False)
    tok.decoder = decoders.ByteLevel()
    fast = PreTrainedTokenizerFast(tokenizer_object=tok, eos_token="<|im_end|>", pad_token="<|endoftext|>")
    fast.add_special_tokens({"additional_special_tokens": SPECIAL})
    fast.add_tokens(THINK)
    fast.chat_template = CHAT_TEMPLATE
    return fast


def build_tiny_qwen(out_dir: str | Path, family: str = "qwen3_vl") -> Path:
    """Write a tiny checkpoint of `family` (qwen3_vl | qwen2_5_vl | qwen3_5) to `out_dir`."""
    ensure_torchvision()
    import torch
    from transformers import AutoModelForImageTextToText

    torch.manual_seed(0)
    out_dir = Path(out_dir)
    tok = _tokenizer()
    ids = {
        name: tok.convert_tokens_to_ids(t)
        for name, t in [
            ("image_token_id", "<|image_pad|>"),
            ("video_token_id", "<|video_pad|>"),
            ("vision_start_token_id", "<|vision_start|>"),
            ("vision_end_token_id", "<|vision_end|>"),
        ]
    }
    text = dict(
        vocab_size=len(tok),
        hidden_size=64,
        intermediate_size=128,
        num_hidden_layers=2,
        num_attention_heads=4,
        num_key_value_heads=2,
        head_dim=16,
        max_position_embeddings=4096,
        eos_token_id=tok.eos_token_id,
        pad_token_id=tok.pad_token_id,
    )
    vision = dict(depth=2, hidden_size=32, intermediate_size=64, num_heads=2, out_hidden_size=64)
    if family == "qwen3_vl":
        from transformers import Qwen2VLImageProcessor, Qwen3VLConfig, Qwen3VLProcessor, Qwen3VLVideoProcessor

        text["rope_parameters"] = {
            "rope_type": "default",
            "rope_theta": 10000.0,
            "mrope_section": [4, 2, 2],
            "mrope_interleaved": True,
        }
        vision.update(num_position_embeddings=64, deepstack_visual_indexes=[1])
        cfg = Qwen3VLConfig(text_config=text, vision_config=vision, **ids)
        proc = Qwen3VLProcessor(
            image_processor=Qwen2VLImageProcessor(patch_size=16),
            video_processor=Qwen3VLVideoProcessor(),
            tokenizer=tok,
            chat_template=CHAT_TEMPLATE,
        )
    elif family == "qwen3_5":
        from transformers import Qwen2VLImageProcessor, Qwen3_5Config, Qwen3VLProcessor, Qwen3VLVideoProcessor

        # partial_rotary_factor 0.25 of head_dim 16 -> 4 rotary dims -> mrope_section sums to 2
        text.update(
            rope_parameters={
                "rope_type": "default",
                "rope_theta": 10000.0,
                "mrope_section": [1, 1, 0],
                "mrope_interleaved": True,
                "partial_rotary_factor": 0.25,
            },
            linear_key_head_dim=16,
            linear_value_head_dim=16,
            linear_num_key_heads=2,
            linear_num_value_heads=2,
            layer_types=["linear_attention", "full_attention"],
        )
        vision.update(num_position_embeddings=64)
        cfg = Qwen3_5Config(text_config=text, vision_config=vision, **ids)
        proc = Qwen3VLProcessor(
            image_processor=Qwen2VLImageProcessor(patch_size=16),
            video_processor=Qwen3VLVideoProcessor(),
            tokenizer=tok,
            chat_template=CHAT_TEMPLATE,
        )
    elif family == "qwen2_5_vl":
        from transformers import Qwen2_5_VLConfig, Qwen2_5_VLProcessor, Qwen2VLImageProcessor, Qwen2VLVideoProcessor

        text["rope_parameters"] = {"rope_type": "default", "rope_theta": 10000.0, "mrope_section": [4, 2, 2]}
        vision.update(fullatt_block_indexes=[1], window_size=56, tokens_per_second=2)
        cfg = Qwen2_5_VLConfig(text_config=text, vision_config=vision, **ids)
        proc = Qwen2_5_VLProcessor(
            image_processor=Qwen2VLImageProcessor(),
            video_processor=Qwen2VLVideoProcessor(),
            tokenizer=tok,
            chat_template=CHAT_TEMPLATE,
        )
    else:
        raise ValueError(f"unknown tiny family {family!r}")
    model = AutoModelForImageTextToText.from_config(cfg)
    model.save_pretrained(out_dir)
    proc.save_pretrained(out_dir)
    return out_dir
