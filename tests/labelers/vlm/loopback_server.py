"""A real OpenAI-compatible chat server on loopback, standing in for vLLM serving a 27B model.

It parses each request body the way vLLM would need it: exactly one `video_url` part holding
a `data:video/jpeg;base64,<jpg>,<jpg>,...` list (every frame a decodable JPEG of one size)
or a `data:video/mp4;base64,...` (decoded with PyAV), plus one text part; `media_io_kwargs`,
when present, must be consistent (one frame index per frame, fps > 0). Bad requests get
HTTP 400 like a real server. What it saw is kept in `server.seen` for the tests.

The reply is chosen by the request's `model` (the scenario), so one server covers every
case: "ok", "legacy" (thinking in `reasoning_content`), "length" (cut off while thinking),
"flaky" (429 with Retry-After on two calls of every three), "error500", "slow" (sleeps
`delay_s`), "unauthorized" (401), "badrequest" (400), "nocontent" (thinking only).
"""

from __future__ import annotations

import asyncio
import base64
import io
import socket
import threading
import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse


@dataclass
class Seen:
    scenario: str
    mime: str
    n_frames: int
    size: tuple[int, int]  # (width, height)
    frame_means: list[float]
    text: str
    media_io_kwargs: dict | None
    body: dict = field(repr=False, default_factory=dict)
    mp4_fps: float | None = None


def _inspect_video(url: str) -> tuple[str, list[np.ndarray], float | None]:
    from PIL import Image

    head, _, payload = url.partition(",")
    if not head.startswith("data:") or not head.endswith(";base64"):
        raise ValueError(f"video_url is not a base64 data URL: {head[:40]!r}")
    mime = head[5:-7]
    if mime == "video/jpeg":
        frames = [
            np.asarray(Image.open(io.BytesIO(base64.b64decode(p, validate=True))).convert("RGB"))
            for p in payload.split(",")
        ]
        return mime, frames, None
    if mime == "video/mp4":
        import av

        with av.open(io.BytesIO(base64.b64decode(payload, validate=True))) as c:
            s = c.streams.video[0]
            frames = [f.to_ndarray(format="rgb24") for f in c.decode(s)]
            return mime, frames, float(s.average_rate)
    raise ValueError(f"unsupported video mime type {mime!r}")


def _check(body: dict) -> Seen:
    msgs = body.get("messages")
    if not isinstance(msgs, list) or len(msgs) != 1 or msgs[0].get("role") != "user":
        raise ValueError("expected one user message")
    parts = msgs[0]["content"]
    videos = [p for p in parts if p.get("type") == "video_url"]
    texts = [p["text"] for p in parts if p.get("type") == "text"]
    if len(videos) != 1 or len(texts) != 1:
        raise ValueError(f"expected one video_url and one text part, got {[p.get('type') for p in parts]}")
    mime, frames, mp4_fps = _inspect_video(videos[0]["video_url"]["url"])
    if not frames or len({f.shape for f in frames}) != 1:
        raise ValueError("frames missing or of different sizes")
    media = (body.get("media_io_kwargs") or {}).get("video")
    if media is not None:
        if not media.get("fps", 0) > 0:
            raise ValueError("media_io_kwargs.video.fps must be > 0")
        idx = media.get("frames_indices")
        if idx is not None and (len(idx) != len(frames) or idx != sorted(idx)):
            raise ValueError(f"frames_indices ({len(idx)}) must match frames sent ({len(frames)}) and increase")
    h, w = frames[0].shape[:2]
    return Seen(
        scenario=body.get("model", ""),
        mime=mime,
        n_frames=len(frames),
        size=(w, h),
        frame_means=[float(f.mean()) for f in frames],
        text=texts[0],
        media_io_kwargs=media,
        body=body,
        mp4_fps=mp4_fps,
    )


def _completion(
    model: str, content: str | None, reasoning: str | None, finish: str = "stop", reasoning_key: str = "reasoning"
) -> dict:
    message = {"role": "assistant", "content": content, reasoning_key: reasoning}
    return {
        "id": "cmpl-1",
        "object": "chat.completion",
        "created": int(time.time()),
        "model": model,
        "choices": [{"index": 0, "message": message, "finish_reason": finish}],
        "usage": {"prompt_tokens": 1234, "completion_tokens": 56, "total_tokens": 1290},
    }


class LoopbackServer:
    """`with LoopbackServer() as srv:` serves on `srv.base_url` until the block ends."""

    def __init__(self, delay_s: float = 0.0, answer: str = '{"fail": 2.0}', inspect: bool = True):
        self.delay_s, self.answer, self.inspect = delay_s, answer, inspect
        self.seen: list[Seen] = []
        self.calls: Counter[str] = Counter()
        self.in_flight = 0
        self.peak_in_flight = 0
        self.app = self._build()

    def _build(self) -> FastAPI:
        app = FastAPI()

        @app.post("/v1/chat/completions")
        async def chat(request: Request):
            body = await request.json()
            scenario = body.get("model", "ok")
            self.calls[scenario] += 1
            self.in_flight += 1
            self.peak_in_flight = max(self.peak_in_flight, self.in_flight)
            try:
                if self.inspect:
                    try:
                        self.seen.append(await asyncio.to_thread(_check, body))
                    except (ValueError, KeyError, TypeError, OSError) as e:
                        return JSONResponse({"error": {"message": str(e), "type": "BadRequestError"}}, status_code=400)
                return await self._reply(scenario)
            finally:
                self.in_flight -= 1

        return app

    async def _reply(self, scenario: str):
        thinking = "The gripper closes beside the bowl, so the failure starts at 2.0 s."
        if scenario == "slow":
            await asyncio.sleep(self.delay_s)
        if scenario in ("ok", "slow"):
            return _completion(scenario, self.answer, thinking)
        if scenario == "legacy":
            return _completion(scenario, self.answer, thinking, reasoning_key="reasoning_content")
        if scenario == "length":
            return _completion(scenario, None, thinking + ' {"fail": 2.0} hmm, but maybe', finish="length")
        if scenario == "nocontent":
            return _completion(scenario, "", thinking)
        if scenario == "flaky":
            if self.calls[scenario] % 3 != 0:
                return JSONResponse(
                    {"error": {"message": "rate limited"}}, status_code=429, headers={"Retry-After": "0.05"}
                )
            return _completion(scenario, self.answer, thinking)
        if scenario == "error500":
            return JSONResponse({"error": {"message": "engine dead"}}, status_code=500)
        if scenario == "unauthorized":
            return JSONResponse({"error": {"message": "bad key"}}, status_code=401)
        return JSONResponse({"error": {"message": f"unknown model {scenario}"}}, status_code=400)

    def __enter__(self) -> LoopbackServer:
        import uvicorn

        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", 0))
        self.port = sock.getsockname()[1]
        self._server = uvicorn.Server(uvicorn.Config(self.app, log_level="warning", lifespan="off"))
        self._thread = threading.Thread(target=self._server.run, kwargs={"sockets": [sock]}, daemon=True)
        self._thread.start()
        deadline = time.monotonic() + 10
        while not self._server.started:
            if time.monotonic() > deadline:
                raise RuntimeError("loopback server did not start")
            time.sleep(0.01)
        return self

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    def __exit__(self, *exc) -> None:
        self._server.should_exit = True
        self._thread.join(timeout=10)
