"""The hand-written Arrow schemas as they were before `pipeline.arrow` derived them from the
row models (a frozen copy). The derived schemas must equal these field for field, metadata
included, so every Parquet file stays byte-identical."""

import pyarrow as pa

from pipeline import SCHEMA_VERSION

EPISODE_SCHEMA = pa.schema(
    [
        pa.field("schema_version", pa.int32(), nullable=False),
        pa.field("suite", pa.string(), nullable=False),
        pa.field("task", pa.string(), nullable=False),
        pa.field("task_index", pa.int32(), nullable=False),
        pa.field("instruction", pa.string(), nullable=False),
        pa.field("episode_id", pa.string(), nullable=False),
        pa.field("init_state", pa.int32(), nullable=False),
        pa.field("policy", pa.string(), nullable=False),
        pa.field("policy_kind", pa.string(), nullable=False),
        pa.field("policy_params", pa.string(), nullable=False),  # JSON
        pa.field("seed", pa.int64(), nullable=False),
        pa.field("chunk_size", pa.int32(), nullable=False),
        pa.field("horizon", pa.int32(), nullable=False),
        pa.field("control_hz", pa.int32(), nullable=False),
        pa.field("settle_steps", pa.int32(), nullable=False),
        pa.field("steps", pa.int32(), nullable=False),
        pa.field("success", pa.bool_(), nullable=False),
        pa.field("first_success_step", pa.int32()),
        pa.field("wall_time_s", pa.float64(), nullable=False),
        pa.field("state_dim", pa.int32(), nullable=False),
        pa.field("path", pa.string(), nullable=False),
        pa.field("videos", pa.map_(pa.string(), pa.string()), nullable=False),
        pa.field("video_fps", pa.int32()),
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)
STEP_SCHEMA = pa.schema(
    [
        pa.field("step", pa.int32(), nullable=False),
        pa.field("action", pa.list_(pa.float32(), 7), nullable=False),
        pa.field("eef_pos", pa.list_(pa.float32(), 3), nullable=False),
        pa.field("eef_quat", pa.list_(pa.float32(), 4), nullable=False),  # w, x, y, z
        pa.field("gripper_qpos", pa.list_(pa.float32(), 2), nullable=False),
        pa.field("goal", pa.bool_(), nullable=False),  # goal holds after this step
        pa.field("query", pa.bool_(), nullable=False),  # a new chunk was requested at this step
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)
FRAME_SCHEMA = pa.schema(
    [
        pa.field("frame", pa.int32(), nullable=False),
        pa.field("step", pa.int32(), nullable=False),
        pa.field("time_s", pa.float64(), nullable=False),
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)
EVIDENCE_SCHEMA = pa.schema(
    [
        pa.field("step", pa.int32(), nullable=False),
        pa.field("time_s", pa.float64(), nullable=False),
        pa.field("gripper_opening", pa.float32(), nullable=False),
        pa.field("grasped", pa.string(), nullable=False),  # object held between the fingers, or ""
        pa.field("contacts", pa.list_(pa.string()), nullable=False),  # "a|b" pairs, sorted names
        pa.field("displacement", pa.map_(pa.string(), pa.float32()), nullable=False),  # m from start
        pa.field("goal_progress", pa.float32(), nullable=False),  # share of goal conjuncts true
        # added by stage 2 (see pipeline/evidence.py): what the simstate rules also need
        pa.field("gripper_command", pa.float32(), nullable=False),  # gripper action (+1 close)
        pa.field("lift", pa.map_(pa.string(), pa.float32()), nullable=False),  # m, z - start z
        pa.field("tilt_deg", pa.map_(pa.string(), pa.float32()), nullable=False),  # up axis vs start
        pa.field("speed", pa.map_(pa.string(), pa.float32()), nullable=False),  # m/s, free joint
        pa.field("eef_distance", pa.map_(pa.string(), pa.float32()), nullable=False),  # grip site, m
        pa.field("position", pa.map_(pa.string(), pa.list_(pa.float32(), 3)), nullable=False),  # world xyz
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)
SCENARIO_SCHEMA = pa.schema(
    [
        pa.field("suite", pa.string(), nullable=False),
        pa.field("task", pa.string(), nullable=False),
        pa.field("instruction", pa.string(), nullable=False),
        pa.field("episode_id", pa.string(), nullable=False),
        pa.field("init_state", pa.int32(), nullable=False),
        pa.field("step", pa.int32(), nullable=False),
        pa.field("fail_time_s", pa.float64(), nullable=False),
        pa.field("fail_step", pa.int32(), nullable=False),
        pa.field("level", pa.string(), nullable=False),
        pa.field("category", pa.string(), nullable=False),
        pa.field("recovery_action", pa.string(), nullable=False),
        pa.field("policy", pa.string(), nullable=False),
        pa.field("policy_kind", pa.string(), nullable=False),
        pa.field("seed", pa.int64(), nullable=False),
        pa.field("localize_prompt_hash", pa.string()),
        pa.field("characterize_prompt_hash", pa.string()),
        pa.field("reviewers", pa.int32(), nullable=False),
        pa.field("adjudicated", pa.bool_(), nullable=False),
        pa.field("state_dim", pa.int32(), nullable=False),
        pa.field("bddl_path", pa.string(), nullable=False),
        pa.field("bddl_sha256", pa.string(), nullable=False),
        pa.field("state_path", pa.string(), nullable=False),
        pa.field("state_sha256", pa.string(), nullable=False),
        pa.field("history_paths", pa.list_(pa.string()), nullable=False),
        pa.field("history_sha256", pa.list_(pa.string()), nullable=False),
        pa.field("certified", pa.bool_()),
        pa.field("certify_tries", pa.int32(), nullable=False),
        pa.field("certify_successes", pa.int32(), nullable=False),
        # added by the recovery-expert certificates (why a scene is not certified); the one
        # column not in the hand-written schema, declared nullable so older manifests still read
        pa.field("certify_reason", pa.string()),
        pa.field("split", pa.string()),  # issue 24: train / eval
        pa.field("generator", pa.string()),  # issue 24: kind:name@params hash of the source episode
    ],
    metadata={"schema_version": str(SCHEMA_VERSION), "name": "libero-recover scenarios"},
)
_F32_LIST = pa.list_(pa.float32())
EVAL_SCHEMA = pa.schema(
    [
        pa.field("schema_version", pa.int32(), nullable=False),
        pa.field("mode", pa.string(), nullable=False),
        pa.field("scene_id", pa.string(), nullable=False),
        pa.field("suite", pa.string(), nullable=False),
        pa.field("task", pa.string(), nullable=False),
        pa.field("instruction", pa.string(), nullable=False),
        pa.field("episode_id", pa.string(), nullable=False),
        pa.field("scene_step", pa.int32(), nullable=False),
        pa.field("level", pa.string()),
        pa.field("category", pa.string()),
        pa.field("policy", pa.string(), nullable=False),
        pa.field("policy_kind", pa.string(), nullable=False),
        pa.field("gripper", pa.string(), nullable=False),
        pa.field("trial", pa.int32(), nullable=False),
        pa.field("seed", pa.int64(), nullable=False),
        pa.field("policy_seed", pa.int64(), nullable=False),
        pa.field("chunk_size", pa.int32(), nullable=False),
        pa.field("horizon", pa.int32(), nullable=False),
        pa.field("temporal_context", pa.string(), nullable=False),
        pa.field("offsets", pa.map_(pa.string(), pa.list_(pa.float64(), 2)), nullable=False),
        pa.field("gripper_settle_steps", pa.int32(), nullable=False),
        pa.field("init_eef_drift_m", pa.float64(), nullable=False),
        pa.field("init_gripper_opening", pa.float64(), nullable=False),
        pa.field("rd_phase", pa.string()),
        pa.field("rd_start_step", pa.int32()),
        pa.field("steps", pa.int32(), nullable=False),
        pa.field("success", pa.bool_(), nullable=False),
        pa.field("first_success_step", pa.int32()),
        pa.field("wall_time_s", pa.float64(), nullable=False),
        pa.field("actions", pa.list_(_F32_LIST), nullable=False),
        pa.field("eef_pos", pa.list_(_F32_LIST), nullable=False),
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)
ANNOTATION_SCHEMA = pa.schema(
    [
        pa.field("key", pa.string(), nullable=False),
        pa.field("suite", pa.string(), nullable=False),
        pa.field("task", pa.string(), nullable=False),
        pa.field("episode_id", pa.string(), nullable=False),
        pa.field("revision", pa.int32(), nullable=False),
        pa.field("fail_time_s", pa.float64(), nullable=False),
        pa.field("fail_step", pa.int32(), nullable=False),
        pa.field("recovery_level", pa.string(), nullable=False),
        pa.field("failure_category", pa.string(), nullable=False),
        pa.field("recovery_action", pa.string(), nullable=False),
        pa.field("resolution", pa.string(), nullable=False),
        pa.field("quarantined", pa.bool_(), nullable=False),
        pa.field("model_fail_time_s", pa.float64()),
        pa.field("model_recovery_level", pa.string()),
        pa.field("model_failure_category", pa.string()),
        pa.field("n_reviews", pa.int32(), nullable=False),
        pa.field("adjudicator", pa.string()),
        pa.field("json", pa.string(), nullable=False),  # the full record, as in the JSON file
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)
_CHANGE = pa.struct([
    pa.field("object", pa.string()), pa.field("moved_m", pa.float32()), pa.field("tilt_deg", pa.float32()),
    pa.field("tilt_gain_deg", pa.float32()), pa.field("fell_off", pa.bool_()), pa.field("held", pa.bool_()),
    pa.field("position", pa.list_(pa.float32())),
])
TRUTH_SCHEMA = pa.schema(
    [
        pa.field("attempt", pa.int32(), nullable=False),
        pa.field("skill", pa.string(), nullable=False),  # pick_place | open | close | turn_on | turn_off
        pa.field("conjunct", pa.string(), nullable=False),  # e.g. "on akita_black_bowl_1 plate_1"
        pa.field("target", pa.string(), nullable=False),  # object moved, or part operated
        pa.field("reference", pa.string()),  # where it goes (pick_place)
        pa.field("start_step", pa.int32(), nullable=False),
        pa.field("end_step", pa.int32(), nullable=False),  # exclusive
        pa.field("phases", pa.list_(pa.struct([pa.field("label", pa.string()), pa.field("step", pa.int32())]))),
        pa.field("grasp_offset_m", pa.list_(pa.float32())),  # xy noise on the grasp point
        pa.field("approach_height_m", pa.float32()),  # z noise on the grasp point
        pa.field("grasp_timing_steps", pa.int32()),  # < 0 closes early, > 0 late
        pa.field("release_timing_steps", pa.int32()),
        pa.field("place_offset_m", pa.list_(pa.float32())),  # xy + release height noise
        pa.field("action_noise", pa.float32(), nullable=False),  # per-step action noise scale
        pa.field("speed_factor", pa.float32(), nullable=False),
        pa.field("subgoal_achieved", pa.bool_(), nullable=False),
        pa.field("outcome", pa.string(), nullable=False),  # one of OUTCOMES
        pa.field("event", pa.string()),  # close | slip | release | knock | let_go | timeout
        pa.field("event_step", pa.int32()),
        pa.field("event_object", pa.string()),
        pa.field("grip_error_m", pa.float32()),  # grip site to the target's body at the close
        pa.field("release_dist_m", pa.float32()),  # target to reference, xy, at the release
        pa.field("knocked", pa.list_(pa.struct([pa.field("object", pa.string()), pa.field("moved_m", pa.float32()),
                                                pa.field("step", pa.int32())]))),
        pa.field("changes", pa.list_(_CHANGE)),  # decisive event -> attempt end
        pa.field("detail", pa.string(), nullable=False),
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)

# localizations.parquet had no declared schema; this is what pyarrow inferred from a run's rows
LOCALIZATION_SCHEMA = pa.schema(
    [pa.field(n, pa.int64()) for n in ("schema_version",)]
    + [pa.field(n, pa.string()) for n in ("key", "suite", "task", "episode_id", "instruction", "source", "model",
                                          "prompt_name", "prompt_hash", "raw_text")]
    + [pa.field("fail_time_s", pa.float64()), pa.field("fail_step", pa.int64()), pa.field("scene_step", pa.int64())]
    + [pa.field(n, pa.string()) for n in ("scene_bddl", "scene_state", "history")]
    + [pa.field("simstate_time_s", pa.float64()), pa.field("evidence", pa.string())]
    + [pa.field(f"{p}_{e}", pa.int64()) for p in ("pre", "during", "post") for e in ("start", "end")]
    + [pa.field("onset_kind", pa.string()), pa.field("events", pa.string())]
)

# a LeRobot data file, as pyarrow inferred it from the frame arrays; since issue 30 also the
# actions as stepped (float64), beside the float32 `action`
LEROBOT_FRAME_SCHEMA = pa.schema([
    pa.field("observation.state", pa.list_(pa.float32(), 8)),
    # issue 24: the arm's joint states beside the end-effector state
    pa.field("observation.states.joint_state", pa.list_(pa.float32(), 7)),
    pa.field("observation.states.gripper_state", pa.list_(pa.float32(), 2)),
    pa.field("action", pa.list_(pa.float32(), 7)),
    pa.field("action_float64", pa.list_(pa.float64(), 7)),
    pa.field("timestamp", pa.float32()), pa.field("frame_index", pa.int64()), pa.field("episode_index", pa.int64()),
    pa.field("index", pa.int64()), pa.field("task_index", pa.int64()),
])
