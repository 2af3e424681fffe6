"""A client of the openpi websocket policy protocol (pi0, pi0.5 and compatible servers).

Inputs: an `Observation` with agentview and wrist images rendered at `env_resolution`
(256 px, right side up, LIBERO's own frame: `SimEnv.render`). Sent (openpi's LIBERO example,
`examples/libero/main.py`, msgpack-numpy over a websocket via `openpi_client.WebsocketClientPolicy`):
    observation/image, observation/wrist_image  `image_size` (224) uint8, `image_tools.resize_with_pad`
                                                of the 256 px frame, as the example resizes
    observation/state   float32 (8,): eef position, eef axis-angle, gripper qpos (2)
    prompt              the task instruction
and, when `eval.temporal_context` asks for it (the eval puts it in `Observation.context`):
    observation/temporal_context        "initial_frame" or "history"
    initial_frame:
    observation/initial_image, observation/initial_wrist_image
                        (224, 224, 3) uint8: the task's official initial state the source
                        episode started from, prepared like the current images
    history:
    observation/history_image, observation/history_wrist_image
                        (k, 224, 224, 3) uint8, k <= 8: the scene's pre-failure history
                        (`stage2.history`, oldest first), rendered from its logged states
    observation/history_state   float32 (k, 8): the state of each history frame, as above
    observation/history_steps   int32 (k,): their steps in the source rollout
A server whose policy does not read them ignores extra keys.
Received: `actions`, an (N, 7) chunk (N >= 1), returned as float64.

Orientation: openpi's LIBERO example feeds robosuite's raw offscreen image rotated by
180 deg (`img[::-1, ::-1]`). robosuite's raw image is ours flipped vertically, so the
same pixels are ours mirrored left-right; `rotate_180: true` sends exactly those.
State: the example uses robosuite's `robot0_eef_quat` (MuJoCo's hand-body quaternion,
its sign matters near the 180 deg rotations LIBERO lives at), so it is read from the
simulator when the observation carries it; otherwise from the grip-site rotation.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.config import OpenpiPolicyConfig
from pipeline.errors import EpisodeError, FatalError
from pipeline.policies.base import Observation
from pipeline.sim.rotations import mat_to_quat, quat_to_mat

# grip-site frame -> hand-body frame of robosuite's Panda (a fixed 90 deg turn about z)
_SITE_TO_HAND = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def quat_xyzw_to_axis_angle(q: np.ndarray) -> np.ndarray:
    """robosuite's `quat2axisangle` (what openpi's LIBERO example uses), sign-sensitive."""
    w = float(np.clip(q[3], -1.0, 1.0))
    den = math.sqrt(1.0 - w * w)
    if math.isclose(den, 0.0):
        return np.zeros(3)
    return np.asarray(q[:3], dtype=np.float64) * 2.0 * math.acos(w) / den


def _hand_quat_from_site(quat_wxyz: np.ndarray) -> np.ndarray:
    q = mat_to_quat(quat_to_mat(quat_wxyz) @ _SITE_TO_HAND)
    return np.array([q[1], q[2], q[3], q[0]])


def libero_state(obs: Observation) -> np.ndarray:
    """The 8-D proprioceptive state of openpi's LIBERO example."""
    if obs.sim is not None:
        quat = obs.sim.eef_hand_quat()
    else:
        quat = _hand_quat_from_site(obs.eef_quat)
    return np.concatenate([obs.eef_pos, quat_xyzw_to_axis_angle(quat), obs.gripper_qpos]).astype(np.float32)


def prepare_image(img: np.ndarray, size: int, rotate_180: bool) -> np.ndarray:
    from openpi_client import image_tools

    if rotate_180:
        img = img[:, ::-1]  # == robosuite's raw image [::-1, ::-1] (see module docstring)
    img = image_tools.convert_to_uint8(image_tools.resize_with_pad(np.ascontiguousarray(img), size, size))
    return np.ascontiguousarray(img)


CAMERAS = ("agentview", "robot0_eye_in_hand")


# camera -> the request key's stem (the current frame's keys without `observation/`)
IMAGE_KEYS = {"agentview": "image", "robot0_eye_in_hand": "wrist_image"}


def history_states(history: dict) -> np.ndarray:
    """(k, 8) LIBERO states of a pre-failure history (its grip-site quaternions, w x y z)."""
    quats = np.asarray(history["eef_quat"], dtype=np.float64).reshape(-1, 4)
    rows = [np.concatenate([p, quat_xyzw_to_axis_angle(_hand_quat_from_site(q)), g])
            for p, q, g in zip(history["eef_pos"], quats, history["gripper_qpos"], strict=True)]
    return np.asarray(rows, dtype=np.float32).reshape(len(rows), 8)


def context_request(context: dict, cfg: OpenpiPolicyConfig) -> dict:
    """The temporal-context keys of a request (module docstring); {} without a context."""
    kind = context.get("kind")
    out: dict = {}
    if kind == "initial_frame":
        for cam, key in IMAGE_KEYS.items():
            out[f"observation/initial_{key}"] = prepare_image(context["initial_images"][cam], cfg.image_size,
                                                              cfg.rotate_180)
    elif kind == "history" and context.get("history_images"):
        for cam, key in IMAGE_KEYS.items():
            frames = context["history_images"][cam]
            out[f"observation/history_{key}"] = np.stack(
                [prepare_image(f, cfg.image_size, cfg.rotate_180) for f in frames])
        hist = context["history"]
        k = len(context["history_images"]["agentview"])
        out["observation/history_state"] = history_states(hist)[-k:]
        out["observation/history_steps"] = np.asarray(hist["steps"], dtype=np.int32)[-k:]
    if out:
        out["observation/temporal_context"] = kind
    return out


def openpi_request(obs: Observation, cfg: OpenpiPolicyConfig) -> dict:
    """The observation dict openpi's LIBERO example sends for `obs` (images at `env_resolution`),
    with the temporal context when the observation carries one."""
    return {
        "observation/image": prepare_image(obs.images["agentview"], cfg.image_size, cfg.rotate_180),
        "observation/wrist_image": prepare_image(obs.images["robot0_eye_in_hand"], cfg.image_size, cfg.rotate_180),
        "observation/state": libero_state(obs),
        "prompt": str(obs.instruction),
        **context_request(obs.context, cfg),
    }


class OpenpiPolicy:
    """`Policy` backed by a remote openpi server; one websocket per worker process."""

    cameras: tuple[str, ...] = CAMERAS
    # the eval hands it `eval.temporal_context` (initial frame or history), sent as extra keys
    accepts_context: bool = True

    def __init__(self, cfg: OpenpiPolicyConfig, name: str | None = None):
        from openpi_client.websocket_client_policy import WebsocketClientPolicy

        self.cfg = cfg
        self.name = name or "openpi"
        self.image_size = cfg.env_resolution  # what the simulator renders; resized in `request`
        try:
            self._client = WebsocketClientPolicy(host=cfg.host, port=cfg.port, api_key=cfg.api_key)
        except OSError as e:
            raise FatalError(f"openpi server ws://{cfg.host}:{cfg.port} unreachable: {e}") from None
        self.server_metadata = self._client.get_server_metadata()

    def reset(self, task, seed: int) -> None:
        self._client.reset()

    def request(self, obs: Observation) -> dict:
        """The observation dict sent to the server (public for tests and tools)."""
        return openpi_request(obs, self.cfg)

    def act(self, obs: Observation) -> np.ndarray:
        try:
            reply = self._client.infer(self.request(obs))
        except RuntimeError as e:  # the server sent its traceback instead of actions
            raise EpisodeError("openpi_server_error", str(e)[-500:]) from None
        actions = np.asarray(reply.get("actions"), dtype=np.float64)
        if actions.ndim == 1:
            actions = actions[None]
        if actions.ndim != 2 or actions.shape[1] != 7 or len(actions) == 0:
            raise EpisodeError("openpi_bad_actions", f"server returned actions of shape {actions.shape}, need (N, 7)")
        return actions

    def params(self) -> dict:
        return {"host": self.cfg.host, "port": self.cfg.port, "env_resolution": self.cfg.env_resolution,
                "image_size": self.cfg.image_size,
                "rotate_180": self.cfg.rotate_180, "server_metadata": _jsonable(self.server_metadata)}

    def close(self) -> None:
        ws = getattr(self._client, "_ws", None)
        if ws is not None:
            ws.close()


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj if isinstance(obj, str | int | float | bool | type(None)) else repr(obj)
