"""Tuning runs' failure scenes that tests start the recovery expert from, saved as MuJoCo states.

A scene used to be remade for each test by running the generator (stage 1's own code) for a
few hundred steps. That rollout is chaotic enough to end in a different scene on another CPU:
CI's machine changed and a pudding lay 1.4 cm from the basket's wall instead of 1.6 cm, and a
bowl perched level instead of leaning (both made by the same seeds). The tests are about the
recovery expert, so they start from the saved state (51 floats); how it was made is its key.

    python -m tests.policies.tuning_scenes add SUITE TASK INIT SEED STEP   # remake one, save it
    python -m tests.policies.tuning_scenes remake                          # remake all saved
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

FILE = Path(__file__).with_name("tuning_scenes.npz")


def key(suite: str, task: str, init: int, seed: int, step: int) -> str:
    return f"{suite}/{task}/i{init}/s{seed}/t{step}"


def load(suite: str, task: str, init: int, seed: int, step: int) -> np.ndarray:
    k = key(suite, task, init, seed, step)
    with np.load(FILE) as saved:
        if k not in saved.files:
            raise KeyError(f"{FILE}: no scene {k!r}; save it with `python -m tests.policies.tuning_scenes add "
                           f"{suite} {task} {init} {seed} {step}`")
        return saved[k].copy()


def remake(suite: str, task: str, init: int, seed: int, step: int) -> np.ndarray:
    """The scene made again by the generator at the default noise (`default_episode`)."""
    from pipeline.sim import build_env, get_task
    from tests.stage1.default_episode import default_episode

    with build_env(get_task(suite, task)) as env, tempfile.TemporaryDirectory() as tmp:
        folder = default_episode(env, Path(tmp), suite, task, init, seed, horizon=step)
        return np.load(folder / "states.npy")[step]


def _save(scenes: dict[str, np.ndarray]) -> None:
    tmp = FILE.with_suffix(".tmp.npz")
    np.savez(tmp, **dict(sorted(scenes.items())))
    tmp.replace(FILE)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("add", help="remake one scene and save it")
    a.add_argument("suite")
    a.add_argument("task")
    for n in ("init", "seed", "step"):
        a.add_argument(n, type=int)
    sub.add_parser("remake", help="remake every saved scene on this machine")
    args = p.parse_args(argv)
    scenes = {}
    if FILE.exists():
        with np.load(FILE) as saved:
            scenes = {k: saved[k] for k in saved.files}
    if args.cmd == "add":
        todo = [(args.suite, args.task, args.init, args.seed, args.step)]
    else:
        todo = []
        for k in scenes:
            suite, task, i, s, t = k.split("/")
            todo.append((suite, task, int(i[1:]), int(s[1:]), int(t[1:])))
    for item in todo:
        scenes[key(*item)] = remake(*item)
        print("saved", key(*item))
    _save(scenes)


if __name__ == "__main__":
    main()
