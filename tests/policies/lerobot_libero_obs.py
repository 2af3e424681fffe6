"""LeRobot's own LIBERO observation of a raw robosuite observation (run in the LeRobot env).

    python lerobot_libero_obs.py IN.npz OUT.npz
IN: robosuite's raw observation from LIBERO's `OffScreenRenderEnv` (its keys: `agentview_image`,
`robot0_eef_pos`, ...), the controller's `ee_ori_mat`, `task`, and `ours/<key>`: what
`pipeline.policies.lerobot_policy.libero_observation` built for the same simulator state.
OUT: `theirs/<key>`: `lerobot/envs/libero.py:LiberoEnv._format_raw_obs` of the raw observation
(flattened like ours), and `policy/<key>` / `ours_policy/<key>` / `export_policy/<key>`: what
the bridge hands the PolicyServer for theirs / ours / `export/<key>` (our observation of the
state as the LeRobot export restores it), through LeRobot's `preprocess_observation` and LIBERO
env processor.

LeRobot's LIBERO module imports `libero` at the top (to build environments); nothing we call
uses it, and LIBERO lives in the simulator's environment, so stand-in modules take its place.
`_format_raw_obs` reads only the camera names and mapping, the obs type and the controller's
`ee_ori_mat` of its instance: a stand-in instance with LiberoEnv's defaults supplies them.
"""

from __future__ import annotations

import sys
import types
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "pipeline" / "lerobot_env"))
import bridge  # noqa: E402


def stub_libero() -> None:
    libero = types.ModuleType("libero")
    pkg = types.ModuleType("libero.libero")
    pkg.benchmark = types.SimpleNamespace()
    pkg.get_libero_path = lambda *a: ""
    envs = types.ModuleType("libero.libero.envs")
    envs.OffScreenRenderEnv = object
    sys.modules.update({"libero": libero, "libero.libero": pkg, "libero.libero.envs": envs})


def flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        out.update(flatten(v, key + "/") if isinstance(v, dict) else {key: np.asarray(v)})
    return out


def main(src: Path, dst: Path) -> None:
    stub_libero()
    from lerobot.envs.libero import LiberoEnv

    with np.load(src, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    cameras = ["agentview_image", "robot0_eye_in_hand_image"]  # LiberoEnv's default camera_name
    controller = types.SimpleNamespace(ee_ori_mat=data.pop("ee_ori_mat"))
    me = types.SimpleNamespace(camera_name=cameras, camera_name_mapping={"agentview_image": "image",
                                                                         "robot0_eye_in_hand_image": "image2"},
                               obs_type="pixels_agent_pos",
                               _env=types.SimpleNamespace(robots=[types.SimpleNamespace(controller=controller)]))
    task = str(data.pop("task"))
    ours = {k[len("ours/"):]: v for k, v in data.items() if k.startswith("ours/")}
    export = {k[len("export/"):]: v for k, v in data.items() if k.startswith("export/")}
    raw = {k: v for k, v in data.items() if not k.startswith(("ours/", "export/"))}
    theirs = LiberoEnv._format_raw_obs(me, raw)
    pre = bridge.env_preprocessor()
    out = {f"theirs/{k}": v for k, v in flatten(theirs).items()}
    for name, obs in (("policy", theirs), ("ours_policy", bridge.nest(ours)), ("export_policy", bridge.nest(export))):
        policy_input = bridge.robot_observation(bridge.libero_policy_input(obs, task, pre))
        out.update({f"{name}/{k}": np.asarray(v) for k, v in policy_input.items()})
    np.savez(dst, **out)


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
