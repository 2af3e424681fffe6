"""Train a LeRobot policy on one of our exported datasets with LeRobot's own tools.

Both steps run LeRobot's command-line tools, unchanged, in the LeRobot environment
(`.venv-lerobot`, `scripts/setup_lerobot.sh`):
1. `python -m lerobot.datasets.v30.convert_dataset_v21_to_v30`: our export is LeRobot v2.1
   (the reference's release layout); lerobot 0.4.4 reads only v3.0 and names this converter.
   It converts a copy (`<work>/local/<name>`), never the export itself.
2. `lerobot-train --dataset.repo_id=local/<name> --dataset.root=<copy> ...`: the dataset as it is.
`tiny_act_args` is a small ACT for a CPU (ResNet-18 from scratch: no weights are downloaded).
The loss of every logged step is read from lerobot-train's log lines (`step:... loss:...`).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.errors import FatalError

REPO = Path(__file__).resolve().parents[2]
DEFAULT_PYTHON = REPO / ".venv-lerobot" / "bin" / "python"
# lerobot-train's log line: "step:10 smpl:80 ep:1 epch:0.05 loss:3.141 grdn:... lr:... updt_s:... data_s:..."
_LOG = re.compile(r"step:(\d+[KMB]?)\s.*?\bloss:([0-9.eE+-]+)")


def tiny_act_args(chunk_size: int = 16) -> list[str]:
    """A small ACT for a CPU: one encoder and decoder layer, width 64, ResNet-18 from scratch,
    learning rate 1e-4 (ACT's 1e-5 is tuned for long runs)."""
    return ["--policy.type=act", f"--policy.chunk_size={chunk_size}", f"--policy.n_action_steps={chunk_size}",
            "--policy.dim_model=64", "--policy.dim_feedforward=256", "--policy.n_heads=2",
            "--policy.n_encoder_layers=1", "--policy.n_decoder_layers=1", "--policy.n_vae_encoder_layers=1",
            "--policy.latent_dim=16", "--policy.pretrained_backbone_weights=null",
            "--policy.optimizer_lr=1e-4", "--policy.optimizer_lr_backbone=1e-4"]


@dataclass
class TrainResult:
    checkpoint: Path  # .../checkpoints/last/pretrained_model: what `policy.lerobot.path` takes
    losses: list[tuple[int, float]] = field(default_factory=list)  # (step, loss) as lerobot-train logged them
    wall_convert_s: float = 0.0
    wall_train_s: float = 0.0
    command: list[str] = field(default_factory=list)


def lerobot_env(threads: int | None = None, hf_home: Path | None = None) -> dict:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "PYTHONUNBUFFERED": "1"}
    if hf_home is not None:
        env["HF_HOME"] = str(hf_home)
    if threads:
        env.update({"OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads)})
    return env


def _run(cmd: list[str], log: Path, env: dict, timeout: float, what: str) -> None:
    with open(log, "ab") as f:
        res = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, env=env, timeout=timeout)
    if res.returncode != 0:
        tail = log.read_text(errors="replace")[-3000:]
        raise FatalError(f"{what} failed (exit {res.returncode}); log {log}:\n{tail}")


def convert(dataset: Path, work: Path, python: Path = DEFAULT_PYTHON, env: dict | None = None,
            timeout: float = 1800) -> Path:
    """LeRobot's v2.1 -> v3.0 converter on a copy of `dataset`; returns the v3.0 dataset root."""
    if not python.is_file():
        raise FatalError(f"the LeRobot environment is missing ({python}); build it with `bash scripts/setup_lerobot.sh`")
    parent = work / "local"
    root = parent / dataset.name
    for p in (root, parent / f"{dataset.name}_old", parent / f"{dataset.name}_v30"):
        if p.exists():
            shutil.rmtree(p)
    shutil.copytree(dataset, root)
    _run([str(python), "-m", "lerobot.datasets.v30.convert_dataset_v21_to_v30", f"--repo-id=local/{dataset.name}",
          f"--root={work}", "--push-to-hub=false", "--force-conversion"], work / "convert.log",
         env or lerobot_env(hf_home=work / "hf"), timeout, "LeRobot's v2.1 -> v3.0 converter")
    return root


def _step(s: str) -> int:
    mult = {"K": 1_000, "M": 1_000_000, "B": 1_000_000_000}
    return int(float(s[:-1]) * mult[s[-1]]) if s[-1] in mult else int(s)


def parse_losses(log_text: str) -> list[tuple[int, float]]:
    return [(_step(m.group(1)), float(m.group(2))) for m in _LOG.finditer(log_text)]


def train(dataset: Path, out: Path, steps: int, batch_size: int = 8, policy_args: list[str] | None = None,
          python: Path = DEFAULT_PYTHON, threads: int | None = 1, log_freq: int = 10, seed: int = 0,
          extra: list[str] | None = None, timeout: float = 7200) -> TrainResult:
    """Convert our v2.1 `dataset` and train on it with `lerobot-train` into `out` (fresh)."""
    if out.exists():
        shutil.rmtree(out)
    work = out.with_name(out.name + "_data")
    work.mkdir(parents=True, exist_ok=True)
    env = lerobot_env(threads, hf_home=work / "hf")
    t0 = time.perf_counter()
    root = convert(dataset, work, python, env)
    t1 = time.perf_counter()
    train_bin = python.parent / "lerobot-train"
    cmd = [str(train_bin), f"--dataset.repo_id=local/{dataset.name}", f"--dataset.root={root}",
           "--dataset.video_backend=pyav", *(policy_args or tiny_act_args()), "--policy.device=cpu",
           "--policy.push_to_hub=false", f"--output_dir={out}", f"--job_name={dataset.name}", f"--steps={steps}",
           f"--batch_size={batch_size}", "--num_workers=0", f"--log_freq={log_freq}", f"--save_freq={steps}",
           "--eval_freq=0", "--wandb.enable=false", f"--seed={seed}", *(extra or [])]
    log = work / "train.log"
    _run(cmd, log, env, timeout, "lerobot-train")
    checkpoint = out / "checkpoints" / "last" / "pretrained_model"
    if not (checkpoint / "config.json").is_file():
        raise FatalError(f"lerobot-train wrote no checkpoint at {checkpoint}; log {log}")
    return TrainResult(checkpoint, parse_losses(log.read_text(errors="replace")), round(t1 - t0, 2),
                       round(time.perf_counter() - t1, 2), cmd)
