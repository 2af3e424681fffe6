"""A real openpi policy server (PyPI `openpi-server`) for tests: serves a proportional
controller on `observation/state` (the server cannot see the simulator) and logs a digest
of every observation it receives (the temporal-context keys too), one JSON line each.

    python openpi_state_server.py --port 8123 --log /tmp/requests.jsonl
"""

from __future__ import annotations

import argparse
import hashlib
import json

import numpy as np
from openpi_client.base_policy import BasePolicy
from openpi_server import WebsocketPolicyServer

TARGET = np.array([0.0, 0.0, 1.05])  # a point above the table the gripper is driven to
CHUNK = 8


def digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:16]


class StateController(BasePolicy):
    def __init__(self, log: str):
        self.log = log

    def infer(self, obs: dict) -> dict:
        state = np.asarray(obs["observation/state"], dtype=np.float64)
        entry = {"prompt": obs["prompt"], "state": state.tolist()}
        for key in ("observation/image", "observation/wrist_image"):
            img = obs[key]
            entry[key] = {"shape": list(img.shape), "dtype": str(img.dtype), "sha": digest(img)}
        # the temporal context (initial frame or history), as it arrived
        for key in sorted(k for k in obs if k.startswith(("observation/initial_", "observation/history_"))):
            a = np.asarray(obs[key])
            entry[key] = {"shape": list(a.shape), "dtype": str(a.dtype), "sha": digest(a)}
        if "observation/temporal_context" in obs:
            entry["temporal_context"] = str(obs["observation/temporal_context"])
        with open(self.log, "a") as f:
            f.write(json.dumps(entry) + "\n")
        actions = np.zeros((CHUNK, 7), dtype=np.float32)
        actions[:, :3] = np.clip((TARGET - state[:3]) * 10.0, -1.0, 1.0)
        actions[:, 6] = 1.0 if state[6] - state[7] > 0.06 else -1.0  # close when open
        return {"actions": actions}


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--log", required=True)
    args = ap.parse_args()
    WebsocketPolicyServer(StateController(args.log), host="127.0.0.1", port=args.port,
                          metadata={"policy": "state-controller", "chunk": CHUNK}).serve_forever()
