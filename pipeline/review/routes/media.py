"""What a reviewer watches: GET /media/<path> (the videos items show, nothing else), and an
item's evidence and frame tables (GET /api/items/{id}/evidence, /frames). Every file goes
through `media.safe_path` (the run's stage1/ and stage2/ only). A table never changes under the same
file stamp, so it carries an ETag and a private cache lifetime (a revalidation is a 304)."""

from __future__ import annotations

import hashlib

from fastapi import APIRouter, Request
from fastapi.responses import FileResponse, Response

from pipeline.review import media, views
from pipeline.review.deps import CtxDep, ItemId, ReadDb, UserDep
from pipeline.review.errors import NotFound

router = APIRouter()

FILE_CACHE = "private, max-age=3600"
TABLE_CACHE = "private, max-age=300"
TABLE_PATHS_MAX = 100_000


@router.get("/media/{rel:path}")
def media_file(rel: str, _user: UserDep, s: ReadDb, ctx: CtxDep):
    """A video an item shows (`media.VideoAllowlist`), nothing else under the run."""
    with s.begin():
        path = media.safe_path(ctx.run_dir, rel) if ctx.videos.allows(rel, lambda: views.video_paths(s)) else None
    if path is None:
        raise NotFound("no such file")
    return FileResponse(path, headers={"Cache-Control": FILE_CACHE})


def _table(request: Request, ctx, s, item_id: int, kind: str) -> Response:
    # an item's context never changes (a new proposal is a new item): its tables' paths are
    # read from the database once per process, both at once (a page asks for both)
    rel = ctx.table_paths.get((item_id, kind))
    if rel is None:
        with s.begin():
            paths = views.table_paths(s, item_id)
        if len(ctx.table_paths) >= TABLE_PATHS_MAX:
            ctx.table_paths.clear()
        ctx.table_paths.update({(item_id, k): v for k, v in paths.items()})
        rel = paths[kind]
    path = media.safe_path(ctx.run_dir, rel)
    if path is None:
        raise NotFound(f"item {item_id} has no {kind} table")
    etag = '"' + hashlib.sha256(repr((kind, *media.stamp(path))).encode()).hexdigest()[:32] + '"'
    headers = {"Cache-Control": TABLE_CACHE, "ETag": etag}
    if etag in request.headers.get("if-none-match", ""):
        return Response(status_code=304, headers=headers)
    return Response(media.table_json(kind, path), media_type="application/json", headers=headers)


@router.get("/api/items/{item_id}/evidence")
def evidence(item_id: ItemId, request: Request, _user: UserDep, s: ReadDb, ctx: CtxDep):
    return _table(request, ctx, s, item_id, "evidence")


@router.get("/api/items/{item_id}/frames")
def frames(item_id: ItemId, request: Request, _user: UserDep, s: ReadDb, ctx: CtxDep):
    return _table(request, ctx, s, item_id, "frames")
