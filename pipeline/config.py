"""Run configuration: one YAML file, validated once at the edge into pydantic models.

Every section forbids unknown keys, so a typo fails before any work with the file, the
dotted key and the reason. Scalars are strict where YAML's coercions would hide a mistake
(`horizon: true` is not 1, `stop_on_success: 1` is not true); an empty file is an error,
not the full default run; repeated suites, task names or init states are refused. The
resolved config is saved beside each stage's outputs (`save_resolved`), so a run can always
be traced back to what produced it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal, Union, get_args, get_origin

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from pipeline.errors import ConfigError
from pipeline.layout import RESOLVED_CONFIG

SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10", "libero_90")
# suites reported also as one: the reference's LIBERO-100 is LIBERO-10 and LIBERO-90 together
# (its 16 evaluation dimensions: spatial, object, goal, 100 x 4 levels)
SUITE_UNIONS = {"libero_100": ("libero_10", "libero_90")}


def reported_suites(present) -> list[tuple[str, tuple[str, ...]]]:
    """(name, member suites) of every suite row a table shows: each present suite (in the
    order given; a set is sorted), then each union with a present member, right after its last
    member. Rates of a union are computed from its members' scenes and trials, never by
    averaging the members' rates."""
    present = sorted(present) if isinstance(present, (set, frozenset)) else list(dict.fromkeys(present))
    out = [(s, (s,)) for s in present]
    for name, members in SUITE_UNIONS.items():
        if any(m in present for m in members):
            last = max(i for i, (s, _) in enumerate(out) if s in members)
            out.insert(last + 1, (name, tuple(m for m in members if m in present)))
    return out


def _scalar_types(annotation) -> set:
    """The plain types an annotation admits: `int | None` -> {int, NoneType}."""
    if get_origin(annotation) in (Union, type(int | None)):
        return set().union(*(_scalar_types(a) for a in get_args(annotation)))
    return {annotation}


def _check_scalar(value, types: set) -> None:
    numeric = bool(types & {int, float})
    if isinstance(value, bool) and numeric and bool not in types:
        raise ValueError(f"must be a number, got {str(value).lower()}")
    if bool in types and not isinstance(value, bool) and not (value is None and type(None) in types):
        raise ValueError(f"must be true or false, got {value!r}")


def _repeats(values: list) -> list:
    seen: set = set()
    return sorted({v for v in values if v in seen or seen.add(v)}, key=str)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    @field_validator("*", mode="before")
    @classmethod
    def _no_bool_number_coercion(cls, value, info: ValidationInfo):
        annotation = cls.model_fields[info.field_name].annotation
        if get_origin(annotation) is list and isinstance(value, list):
            item_types = _scalar_types(get_args(annotation)[0])
            for item in value:
                _check_scalar(item, item_types)
        else:
            _check_scalar(value, _scalar_types(annotation))
        return value


class RunConfig(_Strict):
    name: str = "default"
    output_dir: Path = Path("runs/default")
    seed: int = 0


class TaskSelection(_Strict):
    suites: list[str] = Field(default_factory=lambda: list(SUITES))
    # task names (from the BDDL file stem) to keep within the suites; None = all
    tasks: list[str] | None = None
    # first N tasks of each suite after filtering; None = all
    max_tasks_per_suite: int | None = Field(default=None, ge=1)
    # official init-state indices to run per task
    init_states: list[int] = Field(default_factory=lambda: list(range(50)))

    @field_validator("suites")
    @classmethod
    def _known_suites(cls, v: list[str]) -> list[str]:
        bad = [s for s in v if s not in SUITES]
        if bad:
            raise ValueError(f"unknown suite(s) {bad}; choose from {list(SUITES)}")
        return v

    @field_validator("suites", "tasks", "init_states")
    @classmethod
    def _no_repeats(cls, v: list | None) -> list | None:
        # a repeat would plan the same episode twice under one id: it could never be done
        if v is not None and _repeats(v):
            raise ValueError(f"repeated {_repeats(v)}; list each once")
        return v

    @field_validator("init_states")
    @classmethod
    def _init_range(cls, v: list[int]) -> list[int]:
        bad = [i for i in v if not 0 <= i < 50]
        if bad:
            raise ValueError(f"init-state indices must be in [0, 50), got {bad}")
        return v


class RolloutConfig(_Strict):
    horizon: int = Field(default=520, ge=1)
    control_hz: Literal[20] = 20
    chunk_size: int = Field(default=8, ge=4, le=32)
    # zero-action steps after reset so objects settle (as LIBERO's and openpi's loops do)
    settle_steps: int = Field(default=10, ge=0)
    # stop an episode once the goal holds (a success needs no more steps)
    stop_on_success: bool = True
    # policy camera resolution (images are resized to what the policy wants)
    policy_image_size: int = Field(default=224, ge=32)


class ScriptedNoise(_Strict):
    """Imperfection knobs of the scripted expert; all zero = the clean expert."""

    grasp_offset_m: float = Field(default=0.0, ge=0.0)  # std of xy grasp-point error
    approach_height_m: float = Field(default=0.0, ge=0.0)  # std of approach/descend height error
    gripper_timing_steps: int = Field(default=0, ge=0)  # max early/late close/open, steps
    action_noise: float = Field(default=0.0, ge=0.0)  # std of Gaussian noise on actions
    speed_scale: float = Field(default=0.0, ge=0.0, le=0.9)  # +- relative speed variation
    place_offset_m: float = Field(default=0.0, ge=0.0)  # std of xy placement error


class ScriptedPolicyConfig(_Strict):
    noise: ScriptedNoise = ScriptedNoise()
    # actions returned per query at most (fewer when a motion primitive ends early)
    chunk_len: int = Field(default=8, ge=1, le=32)
    # tries per goal conjunct (re-grasp after a miss or a drop) before moving on
    max_attempts: int = Field(default=3, ge=1)
    # a suite's own noise in place of `noise` (all knobs), for suites whose tasks rarely fail
    # at the common setting; empty = every suite uses `noise`
    noise_by_suite: dict[str, ScriptedNoise] = Field(default_factory=dict)

    @field_validator("noise_by_suite")
    @classmethod
    def _known_noise_suites(cls, v: dict[str, ScriptedNoise]) -> dict[str, ScriptedNoise]:
        bad = [s for s in v if s not in SUITES]
        if bad:
            raise ValueError(f"unknown suite(s) {bad}; choose from {list(SUITES)}")
        return v

    def noise_for(self, suite: str) -> ScriptedNoise:
        return self.noise_by_suite.get(suite, self.noise)


class OpenpiPolicyConfig(_Strict):
    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=1, le=65535)
    api_key: str | None = None
    # openpi's LIBERO example: the simulator renders both cameras at 256 px
    # (LIBERO_ENV_RESOLUTION), turned 180 degrees, then resized with padding to 224 px
    env_resolution: int = Field(default=256, ge=32)
    image_size: int = Field(default=224, ge=32)
    rotate_180: bool = True


class LerobotPolicyConfig(_Strict):
    """A LeRobot checkpoint served by LeRobot's async-inference PolicyServer
    (pipeline/policies/lerobot_policy.py)."""

    # a checkpoint folder (`.../checkpoints/last/pretrained_model`: config.json, model.safetensors
    # and the pre/post-processor files) or a hub id; required when kind is lerobot
    path: str | None = None
    device: Literal["cpu", "cuda"] = "cpu"
    # what LeRobot's LIBERO env renders (observation_height/width); the server resizes to the
    # checkpoint's image shape, so render at that shape to avoid a resize
    image_size: int = Field(default=256, ge=32, le=1024)
    # "host:port" of a PolicyServer you run (`python -m lerobot.async_inference.policy_server`;
    # it serves one client: one per worker); default: each worker starts its own on loopback
    server: str | None = None
    # LeRobot's rename map (dataset key -> the checkpoint's key), as `lerobot-eval --rename_map`
    rename_map: dict[str, str] = Field(default_factory=dict)
    # the LeRobot environment's interpreter; default <repository>/.venv-lerobot/bin/python
    python: Path | None = None
    connect_timeout_s: float = Field(default=300.0, gt=0)


class PolicyConfig(_Strict):
    # recovery: the zero-noise recovery expert (a reference for eval; it takes no settings)
    kind: Literal["scripted", "openpi", "recovery", "lerobot"] = "scripted"
    name: str | None = None  # recorded with each episode; defaults to kind
    scripted: ScriptedPolicyConfig = ScriptedPolicyConfig()
    openpi: OpenpiPolicyConfig = OpenpiPolicyConfig()
    lerobot: LerobotPolicyConfig = LerobotPolicyConfig()
    # eval only: this policy's temporal context, in place of eval.temporal_context, so one
    # server is evaluated without context, with the initial frame and with the history side
    # by side (three entries with three names: one report row each)
    temporal_context: Literal["none", "initial_frame", "history"] | None = None

    @model_validator(mode="after")
    def _lerobot_needs_a_path(self) -> PolicyConfig:
        if self.kind == "lerobot" and not self.lerobot.path:
            raise ValueError("lerobot.path: a LeRobot checkpoint folder or hub id is required for kind lerobot")
        return self


class VideoConfig(_Strict):
    # the review page shows both views side by side; 256 px is the smallest size at which
    # reviewers can tell the scene's objects apart
    cameras: list[Literal["agentview", "robot0_eye_in_hand"]] = Field(
        default_factory=lambda: ["agentview", "robot0_eye_in_hand"])
    fps: int = Field(default=4)
    resolution: int = Field(default=256, ge=32, le=1024)
    # render which episodes: failures only (all later stages need) or all of them
    render: Literal["failures", "all", "none"] = "failures"
    # fast: no multisampling, no reflections; 2.3x cheaper per software-rendered frame for a
    # mean pixel difference of 1.4/255 (videos are watched, not fed to policies); it also skips
    # the geoms outside each camera's view, which changes no pixel (pipeline/sim/render.py)
    quality: Literal["fast", "standard"] = "fast"

    @field_validator("fps")
    @classmethod
    def _divides_control(cls, v: int) -> int:
        if v <= 0 or 20 % v:
            raise ValueError(f"fps must divide the 20 Hz control rate (1, 2, 4, 5, 10, 20), got {v}")
        return v


class RetryConfig(_Strict):
    """How a unit that raised `RetryableError` (a VLM server's 429/503, a timeout) is tried
    again in its worker: up to `tries` attempts in all, waiting `backoff_s`, then twice as
    long each time, at most `max_backoff_s` (a `retry_after` the error names counts, capped
    the same); after the last try the unit is set aside with the reason."""

    tries: int = Field(default=3, ge=1)
    backoff_s: float = Field(default=1.0, ge=0)
    max_backoff_s: float = Field(default=30.0, ge=0)


class ExecutorConfig(_Strict):
    kind: Literal["local", "ray", "inline"] = "local"  # inline: one worker, the calling process
    workers: int = Field(default=2, ge=1)
    ray_address: str | None = None
    # times an item is run again after its worker died under it (kill -9, OOM, a lost Ray
    # node) before it is set aside with the reason; the run itself goes on either way
    max_retries: int = Field(default=2, ge=0)
    retry: RetryConfig = RetryConfig()  # RetryableError raised by a unit (not a dead worker)


class Stage1Config(_Strict):
    policy: PolicyConfig = PolicyConfig()
    rollout: RolloutConfig = RolloutConfig()
    video: VideoConfig = VideoConfig()


class SamplingConfig(_Strict):
    """How a video is turned into VLM input (see pipeline/labelers/vlm/video_input.py)."""

    # target frames per second; the effective rate is source_fps / round(source_fps / fps),
    # so 1, 2 or 4 on a 20 Hz video (Qwen2.5-VL's time ids want 1, 2 or 4)
    fps: float = Field(default=2.0, gt=0)
    max_frames: int = Field(default=768, ge=4)
    max_pixels: int = Field(default=224 * 224, ge=28 * 28)  # per frame, aspect kept
    draw_timestamp: bool = False  # write "12.5s" into each frame
    jpeg_quality: int = Field(default=90, ge=10, le=100)


class OpenAIBackendConfig(_Strict):
    base_url: str = "http://127.0.0.1:8000/v1"
    model: str = "Qwen/Qwen3.5-27B"
    api_key: str | None = None
    max_in_flight: int = Field(default=8, ge=1)
    timeout_s: float = Field(default=300.0, gt=0)
    max_retries: int = Field(default=4, ge=0)
    max_tokens: int = Field(default=4096, ge=16)
    temperature: float = Field(default=0.0, ge=0.0)
    video_mode: Literal["mp4", "frames"] = "frames"
    # send the true fps / frame indices per request as `media_io_kwargs` (the server must run
    # with --trust-request-mm-kwargs); off: the server's --media-io-kwargs fps must equal
    # sampling.fps (frames mode) -- see README
    send_media_io_kwargs: bool = False
    backoff_base_s: float = Field(default=1.0, ge=0.0)  # retry i waits base * 2**i (+ jitter)
    backoff_max_s: float = Field(default=30.0, ge=0.0)
    enable_thinking: bool | None = None  # passed as chat_template_kwargs when set


class TransformersBackendConfig(_Strict):
    model_path: Path | None = None
    max_new_tokens: int = Field(default=1024, ge=1)
    device: str = "cpu"
    dtype: Literal["auto", "float32", "bfloat16", "float16"] = "auto"
    enable_thinking: bool | None = None  # passed to the chat template when set


class VLMConfig(_Strict):
    backend: Literal["simstate", "openai", "transformers"] = "simstate"
    language: Literal["zh", "en"] = "zh"
    # prompts/<task>.<version>.<language>.md: v2 (JSON-only answers, characterization not told
    # the onset) or v1; a missing file is a ConfigError when the backend is built
    prompt_version: str = Field(default="v2", pattern=r"^v[0-9]+$")
    prompts_dir: Path | None = None  # default: the repository's prompts/
    sampling: SamplingConfig = SamplingConfig()
    openai: OpenAIBackendConfig = OpenAIBackendConfig()
    transformers: TransformersBackendConfig = TransformersBackendConfig()
    # also run the simstate localizer beside a VLM and report agreement
    compare_with_simstate: bool = True


class Stage2Config(_Strict):
    vlm: VLMConfig = VLMConfig()
    history_frames: int = Field(default=8, ge=0)
    # pre-failure history: every k-th step before the onset, rendered from the logged states
    history_stride_steps: int = Field(default=1, ge=1)
    history_cameras: list[Literal["agentview", "robot0_eye_in_hand"]] = Field(default_factory=lambda: ["agentview"])
    history_resolution: int = Field(default=224, ge=32, le=1024)
    # during-failure ends when every object's speed stays under this (m/s) ...
    settle_speed_mps: float = Field(default=0.01, gt=0)
    # ... for this many consecutive steps
    settle_steps: int = Field(default=10, ge=1)


class Stage3Config(_Strict):
    """Characterization and the human review queue (see pipeline/stage3, pipeline/review)."""

    vlm: VLMConfig = VLMConfig()  # backend simstate (default) | openai | transformers
    # any SQLAlchemy URL, e.g. postgresql+psycopg://user@host/db; default: SQLite at
    # <output_dir>/stage3/review.sqlite (WAL, busy timeout)
    db_url: str | None = None
    reviews_per_item: int = Field(default=2, ge=1)  # K independent reviews per item
    time_tolerance_s: float = Field(default=0.5, ge=0)  # failure times agree within +-this
    lease_seconds: int = Field(default=900, ge=10)  # an absent reviewer's hold expires
    lease_max_seconds: int = Field(default=3600, ge=10)  # renewals never hold an item longer
    max_leases_per_person: int = Field(default=3, ge=1)  # items one person may hold at once
    host: str = "127.0.0.1"  # `recover review serve` (loopback unless you mean otherwise)
    port: int = Field(default=8765, ge=1, le=65535)
    # server processes; SQLite writes from all of them queue on one lock file (review/db.py)
    workers: int = Field(default=2, ge=1, le=64)


class SplitConfig(_Strict):
    # share of released scenes that get recovery demonstrations (train); the rest is the
    # evaluation set. Default 0.19: the reference recorded recoveries on 413 of 2,178 scenes.
    train_share: float = Field(default=0.19, ge=0.0, le=1.0)
    # a scene's side is a hash of (seed, scene id), not of the run seed: reruns with another
    # run seed, or releases that add scenes, keep every existing scene on its side
    seed: int = 0


class ReleaseConfig(_Strict):
    output_dir: Path | None = None  # default: <run.output_dir>/release
    split: SplitConfig = SplitConfig()  # train/eval split of the released scenes (release/split.py)
    # more run folders (other generators or seeds over the same task selection) whose final
    # reviewed scenes join this run's in one release; episode keys must stay unique
    # (`stage1.policy.name` tells generators apart), scenes record their generator
    merge_runs: list[Path] = Field(default_factory=list)
    certify_tries: int = Field(default=2, ge=0)  # expert tries per scene; 0 = skip
    # steps per certificate try: the horizon `recover eval` gives a policy from a scene
    # (eval.horizon, and the benchmark's own task horizon, 520), so "certified" means a
    # competent policy can finish within the budget the benchmark grants, no more, no less
    certify_horizon: int = Field(default=520, ge=1)
    # which zero-noise expert certifies: the recovery expert, or the plain stage-1 expert
    certify_expert: Literal["recovery", "plain"] = "recovery"
    # recovery demonstrations (`recover demos`): successful recovery-expert rollouts per
    # released scene, at most `recovery_demo_tries` tries per scene, each seeded with this
    # much variation of approach and speed (0 = the certificate's expert), horizon certify_horizon
    recovery_demos: int = Field(default=3, ge=0)
    recovery_demo_tries: int = Field(default=8, ge=1)
    recovery_demo_variation: float = Field(default=0.5, ge=0.0, le=1.0)
    settle_check_steps: int = Field(default=5, ge=1)
    settle_threshold_m: float = Field(default=0.005, gt=0)
    # LeRobot v2.1 export (`recover export-lerobot`); default folder <run.output_dir>/lerobot
    lerobot_dir: Path | None = None
    lerobot_image_size: int = Field(default=256, ge=32, le=1024)
    lerobot_episodes: Literal["failures", "all"] = "all"  # which stage-1 rollouts to export
    # standard: LIBERO's look (4x multisampling, reflections), what policies are trained on;
    # fast: neither, about 2x cheaper per software-rendered frame, slightly different pixels
    # (pipeline/sim/render.py). Training on fast frames and evaluating on standard ones is a shift.
    lerobot_render_quality: Literal["standard", "fast"] = "standard"


class EvalConfig(_Strict):
    # default: the clean scripted expert and the recovery expert, the two reference rows
    policies: list[PolicyConfig] = Field(default_factory=lambda: [PolicyConfig(), PolicyConfig(kind="recovery")])
    trials_per_condition: int = Field(default=5, ge=1)
    gripper_conditions: list[Literal["open", "closed"]] = Field(default_factory=lambda: ["open", "closed"])
    max_offset_m: float = Field(default=0.02, ge=0.0)
    gripper_settle_steps: int = Field(default=20, ge=1)
    horizon: int = Field(default=520, ge=1)
    chunk_sizes: list[int] = Field(default_factory=lambda: [8])
    temporal_context: Literal["none", "initial_frame", "history"] = "none"
    # which scenes of a release with a train/eval split to evaluate: `eval` (default: the
    # scenes no recovery demonstration was recorded on), `train`, or `all`; stage-2 scene
    # folders carry no split and are evaluated whole
    split: Literal["eval", "train", "all"] = "eval"
    # scenes: a released set (with scenarios.parquet) or stage-2 output; default: the run's
    # release folder if it exists, else <run>/stage2
    scenes_dir: Path | None = None
    max_scenes: int | None = Field(default=None, ge=1)  # first N scenes (sorted), for smoke runs
    # RD reruns from states every rd_every_steps along the source rollouts (stage-1 folder;
    # default <run>/stage1), at the first chunk size only, rd_trials per start state
    rd: bool = True
    stage1_dir: Path | None = None
    rd_every_steps: int = Field(default=20, ge=1)
    rd_trials: int = Field(default=1, ge=1)
    epsilon: float = Field(default=1e-3, gt=0)
    # standard LIBERO success beside RSR: per policy x task of the evaluated scenes, trials
    # from LIBERO's official init states 0..official_trials-1 (unperturbed, gripper open,
    # first chunk size, eval.horizon steps); 0: none
    official_trials: int = Field(default=2, ge=0)


class Config(_Strict):
    _source: Path | None = PrivateAttr(default=None)  # the file it was read from, for errors
    run: RunConfig = RunConfig()
    tasks: TaskSelection = TaskSelection()
    executor: ExecutorConfig = ExecutorConfig()
    stage1: Stage1Config = Stage1Config()
    stage2: Stage2Config = Stage2Config()
    stage3: Stage3Config = Stage3Config()
    release: ReleaseConfig = ReleaseConfig()
    eval: EvalConfig = EvalConfig()

    @model_validator(mode="after")
    def _chunks_in_range(self) -> Config:
        bad = [c for c in self.eval.chunk_sizes if not 4 <= c <= 32]
        if bad:
            raise ValueError(f"eval.chunk_sizes must be within [4, 32], got {bad}")
        return self

    @property
    def out(self) -> Path:
        return Path(self.run.output_dir)

    def __eq__(self, other: object) -> bool:  # where it was read from is not what it says
        return isinstance(other, Config) and self.__dict__ == other.__dict__

    __hash__ = _Strict.__hash__

    def error(self, key: str, message: str) -> ConfigError:
        """A ConfigError for a check that needs more than the file (e.g. LIBERO's task names)."""
        return ConfigError(f"{self._source or '<config>'}: invalid configuration\n  {key}: {message}")


def _format_errors(path: Path, err: ValidationError) -> str:
    lines = [f"{path}: invalid configuration"]
    for e in err.errors():
        key = ".".join(str(p) for p in e["loc"]) or "<root>"
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
        lines.append(f"  {key}: {msg}")
    return "\n".join(lines)


def load_config(path: str | Path, overrides: dict | None = None) -> Config:
    """Read and validate a YAML config; raise ConfigError naming the file and key."""
    path = Path(path)
    raw = _read_raw(path, ())
    for dotted, value in (overrides or {}).items():
        node = raw
        *parents, leaf = dotted.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    try:
        cfg = Config.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(_format_errors(path, e)) from None
    cfg._source = path
    return cfg


def _read_raw(path: Path, seen: tuple[Path, ...]) -> dict:
    """The YAML mapping of `path`; a top-level `extends: OTHER.yaml` (relative to this file)
    is read first and this file's keys are merged over it, section by section, so a variant
    (e.g. the report run) states only what differs from the config it varies."""
    try:
        raw = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        where = f" (`extends` of {seen[-1]})" if seen else ""
        raise ConfigError(f"{path}: no such config file{where}") from None
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: not valid YAML: {e}") from None
    if raw is None or raw == {}:
        # an empty file would otherwise mean "all defaults": the full 6,500-episode run
        raise ConfigError(f"{path}: empty config; give at least one section (e.g. `run: {{name: my-run}}`)")
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: top level must be a mapping, got {type(raw).__name__}")
    base = raw.pop("extends", None)
    if base is None:
        return raw
    if not isinstance(base, str):
        raise ConfigError(f"{path}: invalid configuration\n  extends: a config file's path, got {base!r}")
    parent = (path.parent / base).resolve()
    if parent in seen or parent == path.resolve():
        raise ConfigError(f"{path}: invalid configuration\n  extends: {base} extends this file again (a cycle)")
    return _merge(_read_raw(parent, (*seen, path.resolve())), raw)


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def save_resolved(cfg: Config, directory: str | Path, name: str = RESOLVED_CONFIG) -> Path:
    """Write the fully resolved config next to a stage's outputs."""
    from pipeline.atomic import write_text

    target = Path(directory) / name
    write_text(target, yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False))
    return target
