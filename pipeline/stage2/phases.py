"""Split a failed episode at its onset into pre-, during- and post-failure phases.

Inputs: the episode's `Evidence` (object speeds, gripper command), the onset step and the
settle parameters from `Stage2Config`. Output: a `Phases` record of half-open ranges over
the state rows 0..steps (so `post` ends at steps + 1 and includes the final state):
    pre    [0, onset)
    during [onset, end)
    post   [end, steps + 1)
where `end` is the earlier of
  - scene stable again: the end of the first window of `settle_steps` steps, starting at or
    after the onset, in which every object's speed, and the speed at which the gripper
    fingers open, stay below `settle_speed_mps` (`motion`);
  - the robot stops the original attempt: the gripper command flips away from its value at
    the onset and holds the new value for `MIN_FLIP_STEPS` steps (a re-grasp, a release);
and never before onset + 1, never after steps + 1.
The scene snapshot is taken at `settled_step`: the start of that first calm window.
Also: seconds <-> steps through stage 1's frame table (`step_for_time`).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from pipeline.evidence import Evidence
from pipeline.records import Phases, step_at_time

MIN_FLIP_STEPS = 3


def motion(ev: Evidence) -> np.ndarray:
    """Per state row, the fastest motion in the scene (m/s): every object's speed and the
    speed at which the gripper fingers open. Opening fingers count because a restored scene
    cannot say which way they were going: the MuJoCo state has no gripper command, and a
    restore (`pipeline.sim.restore`, `hold_grasp`) closes half-open fingers, which knocks an
    object beside them. Closing fingers do not count: the restore closes them too."""
    objects = np.max(np.stack([ev.col("speed", o) for o in ev.objects]), axis=0) if ev.objects else np.zeros(len(ev))
    opening = np.asarray(ev.gripper_opening, dtype=np.float64)
    fingers = np.maximum(np.diff(opening, prepend=opening[:1]), 0.0) * ev.control_hz
    return np.maximum(objects, fingers)


def stable_end(ev: Evidence, onset: int, speed_mps: float, settle_steps: int) -> int | None:
    calm = motion(ev) < speed_mps
    run = 0
    for t in range(onset, len(ev)):
        run = run + 1 if calm[t] else 0
        if run >= settle_steps:
            return t + 1
    return None


def settled_step(ev: Evidence, onset: int, speed_mps: float, settle_steps: int) -> int | None:
    """The first step at or after the onset from which every object stays calm for
    `settle_steps` steps: the failure state a recovery starts from. At the onset itself
    objects may still be falling or sliding, which no one can restore as a fixed scene."""
    end = stable_end(ev, onset, speed_mps, settle_steps)
    return None if end is None else end - settle_steps


def attempt_end(ev: Evidence, onset: int) -> int | None:
    closed = ev.gripper_command > 0
    start = bool(closed[onset])
    run = 0
    for t in range(onset + 1, len(ev)):
        run = run + 1 if closed[t] != start else 0
        if run >= MIN_FLIP_STEPS:
            return t - MIN_FLIP_STEPS + 1
    return None


def split_phases(ev: Evidence, onset: int, settle_speed_mps: float, settle_steps: int) -> Phases:
    n = len(ev)  # steps + 1 state rows
    if not 0 <= onset < n:
        raise ValueError(f"onset step {onset} outside the episode's states [0, {n})")
    ends = [e for e in (stable_end(ev, onset, settle_speed_mps, settle_steps), attempt_end(ev, onset)) if e]
    end = min(ends) if ends else n
    end = int(min(max(end, onset + 1), n))
    return Phases(pre=(0, onset), during=(onset, end), post=(end, n))


def step_for_time(time_s: float, frames: pa.Table | None, steps: int, control_hz: int = 20) -> int:
    """The simulator step at `time_s` of the episode's video, clamped to [0, steps].

    Interpolated along the frame table (frame times -> steps), so a sparse video (4 fps)
    still maps a time to the step between its frames; without a table, time * control_hz.
    """
    if frames is not None and frames.num_rows >= 2:
        t = np.asarray(frames.column("time_s").to_pylist(), dtype=np.float64)
        s = np.asarray(frames.column("step").to_pylist(), dtype=np.float64)
        slope = (s[-1] - s[0]) / (t[-1] - t[0]) if t[-1] > t[0] else control_hz
        # inside the table interpolate; beyond it extend with the table's own rate
        step = round(float(np.interp(time_s, t, s)) + slope * (min(time_s - t[0], 0) + max(time_s - t[-1], 0)))
    else:
        step = step_at_time(time_s, control_hz)
    return int(min(max(step, 0), steps))
