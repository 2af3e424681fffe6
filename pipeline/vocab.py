"""The closed vocabularies of the records: levels, categories, event kinds, quarantine
reasons, review decisions and resolutions.

Each is a `StrEnum`, so a member *is* its string: JSON and Parquet files hold the same text
as before these existed, and comparing a member with a literal string still works. A value
outside the vocabulary fails validation where a record is built or read, naming the field.
"""

from __future__ import annotations

from enum import StrEnum


class Level(StrEnum):
    L1 = "L1"  # action retry
    L2 = "L2"  # action adaptation
    L3 = "L3"  # object state recovery
    L4 = "L4"  # environmental recovery


class Split(StrEnum):
    """A released scene's side of the train/eval split (`pipeline.release.split`)."""

    train = "train"  # recovery demonstrations are recorded here (fine-tuning data)
    eval = "eval"  # held out: `recover eval` scores policies here by default


class Category(StrEnum):
    grasp_failure = "grasp_failure"
    placement_failure = "placement_failure"
    object_displacement = "object_displacement"
    collision_or_interaction_failure = "collision_or_interaction_failure"
    environmental_obstruction = "environmental_obstruction"
    other = "other"


class EventKind(StrEnum):
    """What the simstate rules saw happen (pipeline/labelers/simstate/events.py documents each rule)."""

    grasp_missed = "grasp_missed"
    grasp_lost = "grasp_lost"
    object_dropped = "object_dropped"
    object_misplaced = "object_misplaced"  # a target let go and set down where the goal does not want it
    object_toppled = "object_toppled"
    unintended_displacement = "unintended_displacement"
    robot_contact_non_target = "robot_contact_non_target"
    object_collision = "object_collision"
    part_not_operated = "part_not_operated"  # a knob or drawer worked, let go, no goal progress
    goal_regression = "goal_regression"


class QuarantineReason(StrEnum):
    """Why an output could not be used (`QuarantineEntry.reason`); counted in the summaries."""

    # a VLM answer (pipeline/vlm/parse.py)
    empty = "empty"  # no answer text at all (or only whitespace / only thinking)
    truncated = "truncated"  # cut at the token limit, or thinking never closed
    no_json = "no_json"  # no JSON object could be found, even after repairs
    schema = "schema"  # a JSON object (or record file), but a missing key, wrong type or bad value
    out_of_range = "out_of_range"  # a time outside [0, video duration]
    ambiguous = "ambiguous"  # several valid answers that disagree
    backend_error = "backend_error"  # the request itself failed (after retries)
    # the video a VLM was to see (pipeline/vlm/video_input.py, stage 2 / 3)
    no_video = "no_video"
    missing_video = "missing_video"
    video_unreadable = "video_unreadable"
    video_too_short = "video_too_short"
    video_table_mismatch = "video_table_mismatch"
    sampling_rate_mismatch = "sampling_rate_mismatch"
    # stage 2: the episode itself
    no_failure_found = "no_failure_found"
    not_settled = "not_settled"
    goal_satisfied_at_onset = "goal_satisfied_at_onset"
    bddl_unparsable = "bddl_unparsable"
    bddl_objects_mismatch = "bddl_objects_mismatch"
    state_shape = "state_shape"
    state_mismatch = "state_mismatch"
    episode_error = "episode_error"  # an unexpected error while processing the episode
    # stage 2: a bad stage-1 input (file and field named in the entry)
    stage1_bad_manifest = "stage1_bad_manifest"
    stage1_bad_states = "stage1_bad_states"
    stage1_bad_steps = "stage1_bad_steps"
    stage1_bad_frames = "stage1_bad_frames"
    stage1_missing_file = "stage1_missing_file"
    # stage 3: a bad stage-2 input (pipeline/stage3/inputs.py) or evidence
    unreadable = "unreadable"
    key_mismatch = "key_mismatch"
    duplicate_key = "duplicate_key"
    fail_time_not_finite = "fail_time_not_finite"
    fail_time_negative = "fail_time_negative"
    fail_time_beyond_episode = "fail_time_beyond_episode"
    missing_evidence = "missing_evidence"
    no_evidence = "no_evidence"
    bad_evidence = "bad_evidence"
    bad_proposal = "bad_proposal"  # a proposal or review context the queue refused (field named)
    # release (pipeline/release/sources.py, build.py)
    no_localization = "no_localization"
    no_episode = "no_episode"
    missing_scene_file = "missing_scene_file"
    unreadable_state = "unreadable_state"


class Decision(StrEnum):
    """A reviewer's decision on an item."""

    accept = "accept"
    revise = "revise"
    flag = "flag"


class ItemStatus(StrEnum):
    """Where a review item is (pipeline/review/workflow.py and adjudication.py move it):
    pending -> leased -> reviewed (k of K) -> final | conflict -> adjudicating -> final;
    superseded when a new revision of the episode replaces it."""

    pending = "pending"
    leased = "leased"
    reviewed = "reviewed"
    conflict = "conflict"
    adjudicating = "adjudicating"
    final = "final"
    superseded = "superseded"


# the states in which an item still collects reviews (its reviews stay hidden meanwhile)
COLLECTING = (ItemStatus.pending, ItemStatus.leased, ItemStatus.reviewed)


class Resolution(StrEnum):
    """How a review item became final."""

    agreed = "agreed"  # the required reviews agreed
    adjudicated = "adjudicated"  # an adjudicator decided the disputed fields
    excluded = "excluded"  # an adjudicator took the episode out (never exported)
