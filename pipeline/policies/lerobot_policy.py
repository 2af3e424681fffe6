"""`policy.kind: lerobot`: any LeRobot checkpoint, served by LeRobot's async-inference PolicyServer.

Processes (per worker): this one (the simulator, main .venv, numpy < 2) -> the bridge
(`pipeline/lerobot_env/bridge.py`, in the LeRobot environment `.venv-lerobot`, lerobot 0.4.4)
-> gRPC -> LeRobot's `PolicyServer` (started by the bridge on loopback, or yours:
`lerobot.server: host:port`, e.g. on a GPU machine). The server is LeRobot's own, unchanged:
it loads the checkpoint (`policy.path`) with its own pre/post-processors on `device` and
answers `predict_action_chunk`; the runner executes `chunk_size` of the chunk, as for every kind.
Why the bridge: the server's wire format is pickles of LeRobot's classes, so its client must
run where lerobot is installed; and the server takes a robot's observation (named state values,
HWC images), not LeRobot's environment observation, so the bridge applies LeRobot's LIBERO
environment processing first, with LeRobot's own code.

Observation (sent to the bridge): exactly what LeRobot's LIBERO env builds
(`lerobot/envs/libero.py:LiberoEnv._format_raw_obs`, obs_type `pixels_agent_pos`) from
robosuite's raw observation at `image_size`:
    pixels/image, pixels/image2     agentview, robot0_eye_in_hand: robosuite's raw image (bottom
                                    row first: our right-side-up frame flipped vertically), uint8
    robot_state/eef/pos, quat, mat  robot0_eef_pos, robot0_eef_quat (x, y, z, w; the hand body's,
                                    MuJoCo's sign), the controller's ee_ori_mat
    robot_state/gripper/qpos, qvel  robot0_gripper_qpos / _qvel
    robot_state/joints/pos, vel     robot0_joint_pos / _vel
    task                            the instruction (LiberoEnv's task_description)
The bridge then runs `preprocess_observation` and the `LiberoProcessorStep` (images turned 180
degrees; state = eef pos, axis-angle of the quaternion, gripper qpos: 8 floats), as
`lerobot-eval --env.type=libero` does. tests/policies/test_lerobot_policy.py checks the raw
observation against LeRobot's own `_format_raw_obs` of LIBERO's observation, array for array.
"""

from __future__ import annotations

import io
import json
import struct
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from pipeline.config import LerobotPolicyConfig
from pipeline.errors import EpisodeError, FatalError
from pipeline.policies.base import Observation

REPO = Path(__file__).resolve().parents[2]
BRIDGE = REPO / "pipeline" / "lerobot_env" / "bridge.py"
CAMERAS = ("agentview", "robot0_eye_in_hand")
# our camera -> LeRobot's LIBERO name (`LiberoEnv.camera_name_mapping`)
LEROBOT_CAMERAS = {"agentview": "image", "robot0_eye_in_hand": "image2"}


def lerobot_python(cfg: LerobotPolicyConfig) -> Path:
    return Path(cfg.python) if cfg.python else REPO / ".venv-lerobot" / "bin" / "python"


def libero_observation(obs: Observation) -> dict[str, np.ndarray]:
    """LeRobot's LIBERO env observation of `obs` (module docstring), flattened with `/`.
    `obs.images` are our right-side-up frames; robosuite's raw image is that flipped vertically."""
    if obs.sim is None:
        raise ValueError("a LeRobot observation needs the simulator's proprioception (Observation.sim)")
    r = obs.sim.robot_observables()
    out = {f"pixels/{LEROBOT_CAMERAS[cam]}": np.ascontiguousarray(obs.images[cam][::-1]) for cam in CAMERAS}
    out.update({
        "robot_state/eef/pos": r["robot0_eef_pos"], "robot_state/eef/quat": r["robot0_eef_quat"],
        "robot_state/eef/mat": r["ee_ori_mat"],
        "robot_state/gripper/qpos": r["robot0_gripper_qpos"], "robot_state/gripper/qvel": r["robot0_gripper_qvel"],
        "robot_state/joints/pos": r["robot0_joint_pos"], "robot_state/joints/vel": r["robot0_joint_vel"],
    })
    return out


class Bridge:
    """The bridge process (pipeline/lerobot_env/bridge.py): length-prefixed `.npz` frames over pipes."""

    def __init__(self, python: Path, settings: dict, log: Path):
        if not python.is_file():
            raise FatalError(f"policy.lerobot: the LeRobot environment is missing ({python}); build it with "
                             "`bash scripts/setup_lerobot.sh` (or `make setup-test`), or set lerobot.python")
        self.log_path = log
        self._log = open(log, "ab")  # noqa: SIM115 (the bridge's stderr, for as long as it runs)
        self.proc = subprocess.Popen([str(python), str(BRIDGE), json.dumps(settings)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=self._log)
        hello = self.receive()
        if "error" in hello:
            self.close()
            raise FatalError(f"policy.lerobot: {hello['error']} (logs: {log})")
        self.describe = json.loads(str(hello["describe"]))

    def receive(self) -> dict:
        head = self.proc.stdout.read(8)
        if len(head) < 8:
            raise FatalError(f"policy.lerobot: the LeRobot bridge exited (code {self.proc.poll()}); "
                             f"its log: {self.log_path}\n{self._tail()}")
        (n,) = struct.unpack("<Q", head)
        with np.load(io.BytesIO(self.proc.stdout.read(n)), allow_pickle=False) as z:
            return {k: z[k] for k in z.files}

    def call(self, arrays: dict) -> dict:
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        data = buf.getvalue()
        self.proc.stdin.write(struct.pack("<Q", len(data)) + data)
        self.proc.stdin.flush()
        return self.receive()

    def _tail(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-3000:]
        except OSError:
            return ""

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self.proc.stdin.close()  # end of input: the bridge closes its server and exits
                self.proc.wait(timeout=30)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
        self._log.close()


class LerobotPolicy:
    """`Policy` backed by a LeRobot checkpoint behind LeRobot's PolicyServer; one per worker."""

    cameras: tuple[str, ...] = CAMERAS

    def __init__(self, cfg: LerobotPolicyConfig, name: str | None = None, log_dir: Path | None = None):
        self.cfg = cfg
        self.name = name or "lerobot"
        self.image_size = cfg.image_size
        self._tmp = None
        if log_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="lerobot-policy-")
            log_dir = Path(self._tmp.name)
        log_dir.mkdir(parents=True, exist_ok=True)
        path = cfg.path
        if path and Path(path).exists():
            path = str(Path(path).resolve())
        settings = {"path": path, "device": cfg.device, "server": cfg.server, "rename_map": dict(cfg.rename_map),
                    "image_size": cfg.image_size, "actions_per_chunk": 1000, "log": str(log_dir / "policy_server.log"),
                    "connect_timeout_s": cfg.connect_timeout_s}
        self.bridge = Bridge(lerobot_python(cfg), settings, log_dir / "bridge.log")
        self.describe = self.bridge.describe

    def reset(self, task, seed: int) -> None:
        pass  # the PolicyServer keeps no episode state for chunking policies (it predicts whole chunks)

    def request(self, obs: Observation) -> dict:
        """The arrays sent to the bridge (public for tests and tools)."""
        return {"op": np.array("act"), "task": np.array(str(obs.instruction)), **libero_observation(obs)}

    def act(self, obs: Observation) -> np.ndarray:
        reply = self.bridge.call(self.request(obs))
        if "error" in reply:
            raise EpisodeError("lerobot_server_error", f"{reply['error']} (logs: {self.bridge.log_path.parent})")
        actions = np.asarray(reply["actions"], dtype=np.float64)
        if actions.ndim != 2 or actions.shape[1] != 7 or len(actions) == 0:
            raise EpisodeError("lerobot_bad_actions", f"policy returned actions of shape {actions.shape}, need (N, 7)")
        return actions

    def params(self) -> dict:
        return {"path": self.cfg.path, "device": self.cfg.device, "image_size": self.cfg.image_size,
                "server": self.cfg.server, "rename_map": dict(self.cfg.rename_map),
                "policy_type": self.describe.get("policy_type"), "chunk_size": self.describe.get("chunk_size")}

    def close(self) -> None:
        self.bridge.close()
        if self._tmp is not None:
            self._tmp.cleanup()
