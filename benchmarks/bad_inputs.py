"""Reproduce every bad input and fault of issue 12 and print one line per case: what happened.

Each case feeds the real component (parser, config loader, review server on loopback with
SQLite, `recover verify`, a rendering process, torch_compat, the transformers backend on a
tiny Qwen, `recover stage2` on real rollouts, `recover stage3` on a sample run) the input
that broke the landed code, and prints `handled: <what it did>`. A case that raises or
misbehaves prints `NOT HANDLED: ...`; the exit status is the number of those.
Cases not built yet print `open: ...` (the slot for the no-op revision).

    MUJOCO_GL=egl .venv/bin/python benchmarks/bad_inputs.py [--only SUBSTRING] [--skip-slow]
"""

from __future__ import annotations

import argparse
import os
import stat
import subprocess
import sys
import tempfile
import textwrap
import traceback
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

CASES: list[tuple[str, bool, Callable[[Path], str] | None]] = []  # (name, slow, check)


def case(name: str, slow: bool = False):
    def register(fn: Callable[[Path], str]):
        CASES.append((name, slow, fn))
        return fn

    return register


def slot(name: str, owner: str) -> None:
    """A case of the issue that another change handles; its check is added there."""
    CASES.append((f"{name} [{owner}]", False, None))


def _python(code: str, timeout: int = 300) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    env.setdefault("MUJOCO_GL", "egl")
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                          timeout=timeout, stdin=subprocess.DEVNULL)


# -- the parser never raises ----------------------------------------------------------------


def _parsed(raw: str) -> str:
    from pipeline.labelers.vlm.parse import parse_localization
    from pipeline.labelers.vlm.schemas import Quarantine

    out = parse_localization(raw, 10.0)
    assert isinstance(out, Quarantine), f"returned {out!r}"
    return f"quarantined as {out.reason.value} ({out.detail[:70]})"


@case("parser: {\"fail\": 1 followed by 5,000 zeros}")
def _(_tmp):
    return _parsed('{"fail": 1' + "0" * 5000 + "}")


@case("parser: {\"fail\": followed by 5,000 nested [")
def _(_tmp):
    return _parsed('{"fail": ' + "[" * 5000)


@case("parser: {\"fail\": 2.0, \"fail\": 9.0}")
def _(_tmp):
    return _parsed('{"fail": 2.0, "fail": 9.0}')


# -- config ---------------------------------------------------------------------------------


def _config_error(tmp: Path, text: str) -> str:
    from pipeline.config import load_config
    from pipeline.errors import ConfigError

    path = tmp / "c.yaml"
    path.write_text(text)
    try:
        cfg = load_config(path)
    except ConfigError as e:
        return "config error: " + " | ".join(line.strip() for line in str(e).splitlines())
    raise AssertionError(f"accepted: {cfg.tasks}")


@case("config: empty file")
def _(tmp):
    return _config_error(tmp, "")


@case("config: horizon: true")
def _(tmp):
    return _config_error(tmp, "stage1: {rollout: {horizon: true}}\n")


@case("config: repeated init states")
def _(tmp):
    return _config_error(tmp, "tasks: {init_states: [0, 1, 1]}\n")


@case("config: unknown task name (recover stage1)")
def _(tmp):
    path = tmp / "c.yaml"
    path.write_text(f"run: {{output_dir: {tmp / 'run'}}}\ntasks: {{suites: [libero_goal], tasks: [nope]}}\n")
    out = subprocess.run([sys.executable, "-c", "from pipeline.cli import main; main()", "stage1", "-c", str(path)],
                         capture_output=True, text=True, timeout=300, cwd=REPO,
                         env=dict(os.environ, PYTHONPATH=str(REPO), COLUMNS="300"))
    assert out.returncode == 2 and "Traceback" not in out.stderr, (out.returncode, out.stderr[-500:])
    return f"exit 2, {' '.join(out.stderr.split())[:110]}"


@case("config: a task selected by name with two suites listed")
def _(tmp):
    from pipeline.config import Config
    from pipeline.stage1.units import selected_tasks

    cfg = Config.model_validate({"tasks": {"suites": ["libero_goal", "libero_spatial"],
                                           "tasks": ["open_the_middle_drawer_of_the_cabinet"]}})
    chosen = [(t.suite, t.name) for t in selected_tasks(cfg)]
    assert chosen == [("libero_goal", "open_the_middle_drawer_of_the_cabinet")], chosen
    return f"selected {chosen[0][0]}/{chosen[0][1]}"


# -- review server --------------------------------------------------------------------------


def _review_server(tmp: Path):
    """A real server on loopback over a sample run: (server, items, tokens, engine)."""
    from pipeline.records import Category, Characterization, Level
    from pipeline.review.api import create_app
    from pipeline.review.auth import add_user
    from pipeline.review.db import make_engine, write_session
    from pipeline.review.enqueue import enqueue
    from pipeline.review.server import ThreadedServer
    from pipeline.review.workflow import QueueSettings
    from pipeline.stage3.inputs import collect, context
    from pipeline.stage3.run import proposal_for
    from tests.review.sample_run import build

    run = tmp / "run"
    build(run, n_episodes=2, n_quarantined=0)
    engine = make_engine(f"sqlite:///{run / 'stage3' / 'review.sqlite'}")
    items = []
    for unit in collect(run):
        ch = Characterization(key=unit.key, recovery_level=Level.L3, failure_category=Category.object_displacement,
                              recovery_action="Put the bowl back", source="simstate")
        with write_session(engine) as s:
            item, _ = enqueue(s, key=unit.key, instruction=unit.localization.instruction,
                              proposal=proposal_for(unit, ch, None), context=context(run, unit, 20, 10.0),
                              required_reviews=2)
            items.append(item.id)
    tokens = {n: add_user(engine, n, r) for n, r in (("ann", "reviewer"), ("dan", "adjudicator"))}
    settings = QueueSettings(required_reviews=2, time_tolerance_s=0.5, lease_seconds=600)
    return ThreadedServer(create_app(run, engine, settings)), items, tokens, engine, run


@case("review: adjudicator reads an open item's reviews, then reviews it")
def _(tmp):
    import httpx

    server, items, tokens, engine, _ = _review_server(tmp)
    with server:
        ann = httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {tokens['ann']}"})
        dan = httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {tokens['dan']}"})
        ann.post(f"/api/items/{items[0]}/review", json={"decision": "accept", "version": 0, "idempotency_key": "a"})
        codes = [dan.get(f"/api/items/{items[0]}/{p}").status_code for p in ("adjudication", "history")]
        assert codes == [403, 403], codes
        got = dan.post(f"/api/items/{items[0]}/review", json={"decision": "accept", "version": 0,
                                                             "idempotency_key": "d"})
    engine.dispose()
    return (f"adjudication/history of the open item: {codes[0]}/{codes[1]}; "
            f"dan's own review: {got.status_code} (allowed, he read nothing)")


@case("review: database files, API docs, deactivated reviewer")
def _(tmp):
    import httpx

    from pipeline.review.auth import set_active

    server, items, tokens, engine, run = _review_server(tmp)
    with server:
        docs = [httpx.get(server.url + p).status_code for p in ("/api/docs", "/api/openapi.json")]
        set_active(engine, "ann", False)
        refused = httpx.get(server.url + "/api/me", headers={"Authorization": f"Bearer {tokens['ann']}"}).status_code
    db = run / "stage3" / "review.sqlite"
    modes = {p.name: oct(stat.S_IMODE(p.stat().st_mode)) for p in db.parent.glob("review.sqlite*")}
    engine.dispose()
    assert docs == [404, 404] and refused == 401 and set(modes.values()) == {"0o600"}, (docs, refused, modes)
    return f"files {modes}; docs {docs[0]}/{docs[1]} without sign-in; deactivated token -> {refused}"


@case("review: a revision that changes nothing (fail_time_s: \"5\" when it is 5)")
def _(tmp):
    import httpx
    from sqlalchemy import select

    from pipeline.review.db import Event, Review, read_session

    server, items, tokens, engine, _ = _review_server(tmp)
    with server:
        ann = httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {tokens['ann']}"})
        model_t = ann.get(f"/api/items/{items[0]}").json()["proposal"]["fail_time_s"]
        first = ann.post(f"/api/items/{items[0]}/review", json={
            "decision": "revise", "version": 0, "idempotency_key": "a", "fields": {"fail_time_s": str(model_t)}}).json()
        again = ann.post(f"/api/items/{items[0]}/review", json={
            "decision": "revise", "version": 1, "idempotency_key": "b", "fields": {"fail_time_s": str(model_t)}}).json()
    with read_session(engine) as s:
        r = s.scalar(select(Review).where(Review.item_id == items[0]))
        changed = s.scalars(select(Event.id).where(Event.item_id == items[0], Event.kind == "review_changed")).all()
    engine.dispose()
    assert (r.decision, r.edited, r.version, again["replayed"], changed) == ("accept", [], 1, True, []), \
        (r.decision, r.edited, r.version, again, changed)
    return (f"the model's time {str(model_t)!r} stored as {first['decision']} (no edit); sent again: replayed, "
            f"version stays {r.version}, no audit event")


# -- verify ---------------------------------------------------------------------------------


@case("verify: a stray file at the release's top level")
def _(tmp):
    from pipeline.release.manifest import MANIFEST_NAME, write_manifest
    from pipeline.release.verify import verify_release

    write_manifest(tmp / MANIFEST_NAME, [])
    (tmp / "notes.txt").write_text("dropped in by hand")
    _, problems = verify_release(tmp)
    assert problems and "notes.txt" in problems[0], problems
    return f"fails: {problems[0].replace(str(tmp) + '/', '')}"


# -- faults ---------------------------------------------------------------------------------


@case("worker exit: a process holding an open EGL renderer", slow=True)
def _(_tmp):
    out = _python("""
        from pipeline.sim import SimEnv
        from pipeline.sim.registry import tasks
        ENV = SimEnv(tasks(["libero_spatial"])[0])
        ENV.reset_to_init(0)
        ENV.render("agentview", 64, "fast")
    """)
    assert out.returncode == 0 and "Exception ignored" not in out.stderr, out.stderr[-800:]
    return "exit 0, no 'Exception ignored in GLContext.__del__' in its output"


@case("local executor: kill -9 of one stage-1 worker", slow=True)
def _(tmp):
    import io
    import json

    from rich.console import Console

    from pipeline.config import Config
    from pipeline.stage1.run import run
    from tests.executors.killer import kill_a_worker_after_the_first_episode

    cfg = Config.model_validate({
        "run": {"name": "kill9", "output_dir": str(tmp / "run")},
        "tasks": {"suites": ["libero_spatial"], "max_tasks_per_suite": 1, "init_states": [0, 1, 2, 3, 4, 5]},
        "stage1": {"rollout": {"horizon": 40}, "video": {"render": "none"}},
    })
    stage1 = tmp / "run" / "stage1"
    killer, killed = kill_a_worker_after_the_first_episode(stage1 / "_done")
    result = run(cfg, console=Console(file=io.StringIO()))
    killer.join()
    report = json.loads((stage1 / "summary.json").read_text())["executor"]
    assert killed and result["done"] == result["planned"] == 6 and not result["errors"], result
    assert len(report["retried"]) == 1 and not report["set_aside"], report
    return f"worker pid {killed[0]} killed: its shard retried, {result['done']}/6 episodes done once"


@case("Ray executor: a worker node removed mid-run", slow=True)
def _(tmp):
    from ray.cluster_utils import Cluster

    from pipeline.executors.ray import RayExecutor
    from tests.executors.work_fns import slow_write

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})  # tasks only on worker nodes
    try:
        _, doomed = [cluster.add_node(num_cpus=1, resources={n: 1}) for n in ("node_a", "node_b")]
        cluster.wait_for_nodes()
        names = [f"u{i}" for i in range(6)]
        seen = []

        def on_event(ev) -> None:
            if ev["node"] == doomed.node_id and not seen:
                seen.append(ev["item"])
                cluster.remove_node(doomed)

        ex = RayExecutor(workers=2, address=cluster.address, worker_env={"PYTHONPATH": str(REPO)})
        results = ex.run(slow_write, [(str(tmp / "out"), n, 1.0) for n in names], on_event)
    finally:
        cluster.shutdown()
    files = sorted(p.name for p in (tmp / "out").iterdir() if not p.name.startswith("."))
    assert seen and results == names == files and not ex.report.set_aside, (seen, results, files)
    return f"node removed under {seen[0]}: {len(ex.report.retried)} task(s) resubmitted, 6/6 outputs, none twice"


# -- the VLM path on a GPU machine ----------------------------------------------------------


@case("torch_compat: a torchvision that registers its own ops (CUDA build)", slow=True)
def _(tmp):
    fake = tmp / "torchvision"
    fake.mkdir()
    (fake / "__init__.py").write_text('import torch\n_l = torch.library.Library("torchvision", "DEF")\n'
                                      '_l.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")\n')
    out = _python(f"""
        import sys; sys.path.insert(0, {str(tmp)!r})
        from pipeline.labelers.vlm import torch_compat
        torch_compat.ensure_torchvision()
        print("shimmed" if torch_compat.shimmed() else "imported untouched")
    """)
    assert out.returncode == 0, out.stderr[-800:]
    return out.stdout.strip() + " (the landed shim aborted this import)"


@case("transformers backend: every 2nd frame of a 49-frame 4 fps video, Qwen2.5-VL", slow=True)
def _(tmp):
    from pipeline.labelers.vlm.torch_compat import ensure_torchvision

    ensure_torchvision()
    from pipeline.config import SamplingConfig, TransformersBackendConfig
    from pipeline.labelers.vlm.backends.transformers_backend import TransformersBackend
    from pipeline.labelers.vlm.prompts import load_prompts
    from tests.labelers.vlm.factories import frames_table, write_video
    from tests.labelers.vlm.tiny_qwen import build_tiny_qwen

    video = write_video(tmp / "v.mp4", 49, fps=4)
    cfg = TransformersBackendConfig(model_path=build_tiny_qwen(tmp / "q", "qwen2_5_vl"), max_new_tokens=1)
    result = TransformersBackend(cfg, SamplingConfig(fps=2.0), load_prompts("en")).localize(
        video, "x", frames_table(49, video_fps=4))
    step = result.extra["second_per_grid_ts"]
    assert step == [1.0], step
    return f"second_per_grid_ts {step} for {len(result.video.frames_indices)} frames (landed: 0.98)"


# -- stage 2 and stage 3 set bad input aside ------------------------------------------------


def _recover(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO), COLUMNS="300")
    env.setdefault("MUJOCO_GL", "egl")
    return subprocess.run([sys.executable, "-c", "from pipeline.cli import main; main()", *args],
                          capture_output=True, text=True, timeout=600, cwd=REPO, env=env, stdin=subprocess.DEVNULL)


def _config(tmp: Path, run: Path, **extra) -> Path:
    import yaml

    path = tmp / "c.yaml"
    path.write_text(yaml.safe_dump({"run": {"output_dir": str(run)}, "executor": {"workers": 1}, **extra}))
    return path


@case("stage 2: truncated states.npy / steps.parquet, bad manifest cell", slow=True)
def _(tmp):
    import json
    import shutil

    import pyarrow as pa
    import pyarrow.parquet as pq

    from pipeline.records import EPISODE_SCHEMA, read_episodes

    # the real rollouts of tests/stage2 (built once, ~1 min, then reused from pytest's cache)
    cache = REPO / ".pytest_cache" / "d" / "stage2-rollouts"
    built = _python(f"from tests.stage2.rollouts import make_fixture_run; print(make_fixture_run({str(cache)!r}))",
                    timeout=900)
    assert built.returncode == 0, built.stderr[-800:]
    src = Path(built.stdout.strip().splitlines()[-1])
    run = tmp / "run"
    shutil.copytree(src, run)
    s1 = run / "stage1"
    eps = {r.policy.removeprefix("fixture_"): r for r in read_episodes(s1 / "episodes.parquet")}
    for rec, name in ((eps["drop"], "states.npy"), (eps["knock"], "steps.parquet")):
        data = (s1 / rec.path / name).read_bytes()
        (s1 / rec.path / name).write_bytes(data[: len(data) // 2])
    rows = pq.read_table(s1 / "episodes.parquet").to_pylist()
    for row in rows:
        if row["episode_id"] == eps["miss"].episode_id:
            row["policy_params"] = "{oops"
    pq.write_table(pa.Table.from_pylist(rows, schema=EPISODE_SCHEMA), s1 / "episodes.parquet")
    cfg = _config(tmp, run, stage2={"history_frames": 0})
    first = _recover("stage2", "-c", str(cfg))
    assert first.returncode == 0, first.stderr[-800:]
    summary = json.loads((run / "stage2" / "summary.json").read_text())
    faults = {f["key"].rsplit("/", 1)[1].split("-")[0].removeprefix("fixture_"): f"{f['reason']}@{f['field']}"
              for f in summary["input_faults"]}
    assert set(faults) == {"drop", "knock", "miss"} and "3 set aside" in first.stdout, (faults, first.stdout[-500:])
    assert summary["quarantine_reasons"].get("no_failure_found") == 1  # the untouched episode went on
    for rec in (eps["drop"], eps["knock"]):  # fix: the original files back
        for name in ("states.npy", "steps.parquet"):
            shutil.copy2(src / "stage1" / rec.path / name, s1 / rec.path / name)
    shutil.copy2(src / "stage1" / "episodes.parquet", s1 / "episodes.parquet")
    second = _recover("stage2", "-c", str(cfg))
    after = json.loads((run / "stage2" / "summary.json").read_text())
    assert second.returncode == 0 and after["set_aside"] == 0 and after["scenes"] == 3, (after, second.stderr[-500:])
    return (f"exit 0, 3 set aside ({', '.join(f'{k}: {v}' for k, v in sorted(faults.items()))}), the rest went on; "
            f"fixed and rerun: {after['scenes']} scenes, 0 set aside")


@case("stage 3: NaN, negative, too late fail_time_s, repeated key, corrected file")
def _(tmp):
    import json
    import math

    import httpx

    from pipeline.review.auth import add_user
    from pipeline.review.db import make_engine
    from tests.review.sample_run import SUITE, TASK, build

    run = tmp / "run"
    build(run, n_episodes=5, n_quarantined=0, wrist=False)  # 3.0 s episodes
    locs = run / "stage2" / "localizations" / SUITE / TASK

    def edit(i: int, **fields) -> None:
        path = locs / f"scripted-i{i:02d}-s0.json"
        path.write_text(json.dumps({**json.loads(path.read_text()), **fields}))

    edit(0, fail_time_s=math.nan)
    edit(1, fail_time_s=-1.0)
    edit(2, fail_time_s=99.0)
    edit(4, key=f"{SUITE}/{TASK}/scripted-i03-s0", episode_id="scripted-i03-s0")
    cfg = _config(tmp, run)
    first = _recover("stage3", "-c", str(cfg))
    assert first.returncode == 0 and "4 set aside" in first.stdout, (first.returncode, first.stdout[-800:])
    summary = json.loads((run / "stage3" / "summary.json").read_text())
    reasons = sorted(f"{f['reason']}@{f['field']}" for f in summary["input_faults"])
    # the review API answers every queued item (the landed code queued the NaN and answered 500)
    from pipeline.review.api import create_app
    from pipeline.review.server import ThreadedServer
    from pipeline.review.workflow import QueueSettings

    engine = make_engine(f"sqlite:///{run / 'stage3' / 'review.sqlite'}")
    token = add_user(engine, "ann", "reviewer")
    with ThreadedServer(create_app(run, engine, QueueSettings(required_reviews=2))) as server:
        client = httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {token}"})
        ids = [it["id"] for it in client.get("/api/queue").json()["available"]]
        codes = sorted({client.get(f"/api/items/{i}").status_code for i in ids})
    engine.dispose()
    assert len(ids) == 5 and codes == [200], (ids, codes)
    edit(0, fail_time_s=1.5)  # the NaN corrected
    second = _recover("stage3", "-c", str(cfg))
    after = json.loads((run / "stage3" / "summary.json").read_text())
    assert second.returncode == 0 and after["set_aside"] == 3 and after.get("characterized") == 1, after
    return (f"exit 0, 4 set aside ({', '.join(reasons)}), all 5 items answer 200; "
            "the corrected file was read again and queued with its value")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="run the cases whose name contains this")
    ap.add_argument("--skip-slow", action="store_true", help="skip cases that start a simulator or a model")
    args = ap.parse_args()
    failed = 0
    for name, slow, check in CASES:
        if args.only not in name or (slow and args.skip_slow):
            continue
        if check is None:
            print(f"open: {name}", flush=True)
            continue
        with tempfile.TemporaryDirectory() as tmp:
            try:
                print(f"handled: {name}: {check(Path(tmp))}", flush=True)
            except Exception as e:  # one line per case, whatever happened
                failed += 1
                where = traceback.extract_tb(e.__traceback__)[-1]
                at = f"{Path(where.filename).name}:{where.lineno}"
                print(f"NOT HANDLED: {name}: {type(e).__name__}: {str(e)[:200]} ({at})", flush=True)
    return failed


if __name__ == "__main__":
    sys.exit(main())
