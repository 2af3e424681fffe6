"""The LeRobot side of `policy.kind: lerobot`: a client of LeRobot's async-inference PolicyServer.

Runs in the LeRobot environment (`.venv-lerobot`: lerobot 0.4.4, numpy 2), started by
`pipeline.policies.lerobot_policy` with this file's path; standalone (stdlib, numpy, lerobot).
    python bridge.py '<json settings>'
Settings: path (checkpoint folder or hub id), device, server ("host:port" of a running PolicyServer,
or null: start one, `python -m lerobot.async_inference.policy_server`, on a free loopback port),
rename_map, actions_per_chunk, log (the started server's log file).

Protocol with the simulator process (stdin/stdout): frames of an 8-byte little-endian length and
an `.npz` (no pickles, so numpy 1 and 2 read each other's). Requests: `op` = "act" with LeRobot's
LIBERO observation flattened (`pixels/image`, `pixels/image2`, `robot_state/eef/pos`, ... as
`lerobot/envs/libero.py:LiberoEnv._format_raw_obs` builds it, and `task`), or "close". Replies:
`actions` (N, 7) float32, or `error`. The first reply (no request) describes the policy.

Per observation, LeRobot's own code does what `lerobot-eval --env.type=libero` does before its
policy: `envs.utils.preprocess_observation`, the task string, then the LIBERO env processor
(`processor.env_processor.LiberoProcessorStep`: images turned 180 degrees, state = eef position,
axis-angle of robosuite's eef quaternion, gripper qpos). The result goes to the PolicyServer as
a robot observation (images HWC uint8, the 8 state values by name, the task), `must_go` so the
server never skips it; the server runs the checkpoint's own pre-processor, `predict_action_chunk`
and post-processor and answers the chunk.
"""

from __future__ import annotations

import io
import json
import os
import pickle  # nosec: the PolicyServer's own wire format, on loopback or a host the user names
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

STATE_NAMES = ["eef_x", "eef_y", "eef_z", "axis_angle1", "axis_angle2", "axis_angle3", "gripper_left", "gripper_right"]
CAMERAS = ("image", "image2")  # LeRobot's LIBERO names: agentview, robot0_eye_in_hand


def read_frame(stream) -> dict | None:
    head = stream.read(8)
    if len(head) < 8:
        return None
    (n,) = struct.unpack("<Q", head)
    with np.load(io.BytesIO(stream.read(n)), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def write_frame(stream, arrays: dict) -> None:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    data = buf.getvalue()
    stream.write(struct.pack("<Q", len(data)) + data)
    stream.flush()


def nest(flat: dict) -> dict:
    """`robot_state/eef/pos` -> {"robot_state": {"eef": {"pos": ...}}} (LiberoEnv's raw observation)."""
    out: dict = {}
    for key, value in flat.items():
        node = out
        *parents, leaf = key.split("/")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return out


def env_preprocessor(policy_config=None):
    """LeRobot's environment pre-processor for LIBERO (`envs.factory.make_env_pre_post_processors`
    with its LIBERO env config: the `LiberoProcessorStep`), as `lerobot-eval` builds it."""
    from lerobot.envs.configs import LiberoEnv
    from lerobot.envs.factory import make_env_pre_post_processors

    return make_env_pre_post_processors(LiberoEnv(), policy_config)[0]


def libero_policy_input(raw: dict, task: str, preprocessor) -> dict:
    """What `lerobot-eval`'s rollout hands a policy's own pre-processor for LIBERO: LeRobot's
    functions on LiberoEnv's raw observation, in its order (one environment: batch 1)."""
    from lerobot.envs.utils import preprocess_observation

    batched = {"pixels": {k: v[None] for k, v in raw["pixels"].items()},
               "robot_state": {g: {k: v[None] for k, v in d.items()} for g, d in raw["robot_state"].items()}}
    obs = preprocess_observation(batched)
    obs["task"] = [task]  # add_envs_task: the env's task_description
    return preprocessor(obs)


def robot_observation(policy_input: dict) -> dict:
    """The processed observation as the PolicyServer's robot observation: HWC uint8 images
    (the server divides by 255 again: exact) and the state values by name."""
    out = {}
    for cam in CAMERAS:
        img = policy_input[f"observation.images.{cam}"][0]  # (3, H, W) float in [0, 1]
        out[cam] = (img.permute(1, 2, 0) * 255).round().clamp(0, 255).byte().numpy()
    state = policy_input["observation.state"][0].numpy()
    out.update({name: float(v) for name, v in zip(STATE_NAMES, state, strict=True)})
    out["task"] = policy_input["task"][0]
    return out


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Client:
    """One connection to a PolicyServer (the server serves one client at a time)."""

    def __init__(self, settings: dict):
        import grpc
        from lerobot.transport import services_pb2
        from lerobot.transport.utils import grpc_channel_options

        self.pb = services_pb2
        self.server = None
        address = settings.get("server")
        if not address:
            port = free_port()
            log = open(settings["log"], "ab")  # noqa: SIM115 (lives as long as the server)
            env = {**os.environ, "PYTHONUNBUFFERED": "1"}
            self.server = subprocess.Popen(
                [sys.executable, "-m", "lerobot.async_inference.policy_server", "--host=127.0.0.1",
                 f"--port={port}", "--fps=20", "--inference_latency=0", "--obs_queue_timeout=600"],
                stdout=log, stderr=subprocess.STDOUT, cwd=Path(settings["log"]).parent, env=env)
            address = f"127.0.0.1:{port}"
        self.address = address
        self.channel = grpc.insecure_channel(address, grpc_channel_options())
        try:
            self._connect(settings)
        except BaseException:
            self.close()  # a server we started goes with us
            raise

    def _connect(self, settings: dict) -> None:
        import grpc
        from lerobot.async_inference.helpers import RemotePolicyConfig
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.datasets.utils import hw_to_dataset_features
        from lerobot.transport import services_pb2, services_pb2_grpc

        try:
            grpc.channel_ready_future(self.channel).result(timeout=float(settings.get("connect_timeout_s", 180)))
        except grpc.FutureTimeoutError:
            raise RuntimeError(f"LeRobot PolicyServer at {self.address} did not come up") from None
        self.stub = services_pb2_grpc.AsyncInferenceStub(self.channel)
        self.config = PreTrainedConfig.from_pretrained(settings["path"])
        image_keys = [k for k in self.config.input_features if k.startswith("observation.images.")]
        size = int(settings["image_size"])
        features = {name: float for name in STATE_NAMES}
        features.update({cam: (size, size, 3) for cam in CAMERAS})
        lerobot_features = hw_to_dataset_features(features, "observation", use_video=False)
        # only the cameras the checkpoint reads (after its rename map) go to the server
        rename = dict(settings.get("rename_map") or {})
        wanted = {k for k in lerobot_features if not k.startswith("observation.images.")
                  or rename.get(k, k) in image_keys}
        self.cameras = [c for c in CAMERAS if f"observation.images.{c}" in wanted]
        self.lerobot_features = {k: v for k, v in lerobot_features.items() if k in wanted}
        spec = RemotePolicyConfig(policy_type=self.config.type, pretrained_name_or_path=settings["path"],
                                  lerobot_features=self.lerobot_features,
                                  actions_per_chunk=int(settings["actions_per_chunk"]), device=settings["device"],
                                  rename_map=rename)
        self.stub.Ready(services_pb2.Empty())
        self.stub.SendPolicyInstructions(services_pb2.PolicySetup(data=pickle.dumps(spec)))
        self.timestep = 0

    def describe(self) -> dict:
        return {"policy_type": self.config.type, "server": self.address,
                "chunk_size": int(getattr(self.config, "chunk_size", 0) or 0),
                "n_action_steps": int(getattr(self.config, "n_action_steps", 0) or 0),
                "input_features": sorted(self.config.input_features), "cameras": self.cameras}

    def act(self, robot_obs: dict) -> np.ndarray:
        from lerobot.async_inference.helpers import TimedObservation
        from lerobot.transport.utils import send_bytes_in_chunks

        obs = {k: v for k, v in robot_obs.items() if k not in CAMERAS or k in self.cameras}
        timed = TimedObservation(timestamp=time.time(), timestep=self.timestep, observation=obs, must_go=True)
        self.timestep += 1
        self.stub.SendObservations(send_bytes_in_chunks(pickle.dumps(timed), self.pb.Observation,
                                                        log_prefix="[libero-recover]", silent=True))
        reply = self.stub.GetActions(self.pb.Empty())
        if not reply.data:  # the server answers Empty when inference raised (it logs why)
            raise RuntimeError("the PolicyServer returned no actions (see its log)")
        chunk = pickle.loads(reply.data)  # nosec: list[TimedAction] from our own server
        return np.stack([a.get_action().numpy() for a in chunk]).astype(np.float32)

    def close(self) -> None:
        if getattr(self, "channel", None) is not None:
            self.channel.close()
        if self.server is not None:
            self.server.terminate()
            try:
                self.server.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.server.kill()


def main() -> None:
    settings = json.loads(sys.argv[1])
    out = sys.stdout.buffer
    sys.stdout = sys.stderr  # LeRobot prints; the pipe is ours
    try:
        client = Client(settings)
        preprocessor = env_preprocessor(client.config)
    except Exception as e:  # noqa: BLE001 (reported to the simulator side, which raises it)
        write_frame(out, {"error": np.array(f"{type(e).__name__}: {e}")})
        return
    write_frame(out, {"describe": np.array(json.dumps(client.describe()))})
    try:
        while True:
            req = read_frame(sys.stdin.buffer)
            if req is None or str(req["op"]) == "close":
                break
            flat = {k: v for k, v in req.items() if k not in ("op", "task")}
            try:
                policy_input = libero_policy_input(nest(flat), str(req["task"]), preprocessor)
                write_frame(out, {"actions": client.act(robot_observation(policy_input))})
            except Exception as e:  # noqa: BLE001
                write_frame(out, {"error": np.array(f"{type(e).__name__}: {e}")})
    finally:
        client.close()


if __name__ == "__main__":
    main()
