"""People and their rights: personal tokens, roles, web sessions, CSRF.

Inputs: a personal token (printed once by `recover review add-reviewer`), or a session
cookie set by signing in with it.
Outputs: the acting `User`, or 401/403.
Invariants:
- only SHA-256 hashes of tokens and session ids are stored (tokens are 256-bit random, so
  a plain hash suffices; a stolen database yields no usable token);
- roles are ordered reviewer < adjudicator < admin (an adjudicator may also review);
- a write authenticated by the session cookie must carry the session's CSRF token in
  `X-CSRF-Token`; a write with `Authorization: Bearer <token>` needs none (browsers never
  attach that header on their own, so it cannot be forged cross-site);
- the session cookie is HttpOnly and SameSite=Strict;
- a token that names nobody is logged (`login_failed`) and costs its client a token of its
  `throttle.FailureThrottle` bucket (checked by `deps`, before any credential is looked at).
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import secrets
from dataclasses import dataclass

from sqlalchemy import bindparam, delete, select
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from pipeline.review import audit
from pipeline.review.db import Lease, User, WebSession, now, read_session, write_session
from pipeline.review.errors import Forbidden, ReviewError

ROLES = ("reviewer", "adjudicator", "admin")
COOKIE = "rv_session"
CSRF_HEADER = "x-csrf-token"
SESSION_SECONDS = 12 * 3600
SAFE_METHODS = {"GET", "HEAD", "OPTIONS"}
log = logging.getLogger(__name__)


class Unauthorized(ReviewError):
    status = 401


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def rank(role: str) -> int:
    return ROLES.index(role)


def require_role(user: User, role: str) -> None:
    if rank(user.role) < rank(role):
        raise Forbidden(f"{user.name} is a {user.role}; this needs the {role} role")


def add_user(engine: Engine, name: str, role: str, actor: str = "admin") -> str:
    """Create a user (or give an existing one a new token and role); return the new token."""
    if role not in ROLES:
        raise ValueError(f"role must be one of {list(ROLES)}, got {role!r}")
    if not name or len(name) > 64:
        raise ValueError("name must be 1-64 characters")
    token = secrets.token_urlsafe(32)
    with write_session(engine) as s:
        user = s.scalar(select(User).where(User.name == name))
        if user is None:
            user = User(name=name, role=role, token_hash=hash_token(token))
            s.add(user)
            audit.record(s, actor, "user_added", None, None, {"name": name, "role": role})
        else:
            before = {"name": name, "role": user.role}
            user.role, user.token_hash, user.active = role, hash_token(token), True
            s.execute(delete(WebSession).where(WebSession.user_id == user.id))
            audit.record(s, actor, "user_token_rotated", None, before, {"name": name, "role": role})
    return token


def list_users(engine: Engine) -> list[dict]:
    """Every person: name, role and whether they may sign in (no token material)."""
    with read_session(engine) as s:
        users = s.scalars(select(User).order_by(User.name))
        return [{"name": u.name, "role": u.role, "active": u.active} for u in users]


def set_active(engine: Engine, name: str, active: bool, actor: str = "admin") -> bool:
    """(De)activate a person; a deactivated person's token and sessions are refused and their
    leases released. Returns whether anything changed; LookupError if there is no such person."""
    with write_session(engine) as s:
        user = s.scalar(select(User).where(User.name == name))
        if user is None:
            raise LookupError(f"no reviewer named {name!r}")
        if user.active == active:
            return False
        user.active = active
        if not active:
            s.execute(delete(WebSession).where(WebSession.user_id == user.id))
            s.execute(delete(Lease).where(Lease.user_id == user.id))
        audit.record(s, actor, "user_reactivated" if active else "user_deactivated", None,
                     {"name": name, "active": not active}, {"name": name, "active": active})
    return True


def user_by_token(s: Session, token: str) -> User | None:
    user = s.scalar(select(User).where(User.token_hash == hash_token(token)))
    return user if user is not None and user.active else None


def sign_in(engine: Engine, token: str) -> tuple[User, str, str]:
    """Exchange a personal token for (user, session id for the cookie, CSRF token)."""
    with write_session(engine) as s:
        user = user_by_token(s, token or "")
        if user is None:
            raise Unauthorized("unknown or disabled token")
        sid, csrf = secrets.token_urlsafe(32), secrets.token_urlsafe(32)
        t = now()
        s.execute(delete(WebSession).where(WebSession.expires_at <= t))
        s.add(WebSession(id_hash=hash_token(sid), user_id=user.id, csrf=csrf, expires_at=t + SESSION_SECONDS))
        return user, sid, csrf


LOGIN_FAILED = "login_failed"  # audit event: a token that names nobody (or a disabled person)


def record_failure(engine: Engine, client: str, how: str) -> None:
    """Log a failed sign-in (never the token tried): an audit event whose actor is the client."""
    log.warning("failed sign-in (%s) from %s", how, client)
    with write_session(engine) as s:
        audit.record(s, f"@{client}"[:64], LOGIN_FAILED, detail=how)


def sign_out(engine: Engine, sid: str) -> None:
    with write_session(engine) as s:
        s.execute(delete(WebSession).where(WebSession.id_hash == hash_token(sid)))


@dataclass
class Principal:
    user: User  # detached from its session: its attributes only are read
    csrf: str | None  # None when authenticated by bearer token


# the acting person is read through a Core connection, not an ORM session: every request
# asks this once (a session, its identity map and an ORM load cost more than the query)
_PERSON = (User.id, User.name, User.role, User.token_hash, User.active, User.created_at)


_BY_TOKEN = select(*_PERSON).where(User.token_hash == bindparam("token_hash"))  # built once (`workflow`)
_BY_SESSION = (select(WebSession.expires_at.label("session_expires_at"), WebSession.csrf, *_PERSON)
               .select_from(WebSession).outerjoin(User, User.id == WebSession.user_id)
               .where(WebSession.id_hash == bindparam("id_hash")))


def _person(row) -> User:
    """A transient `User` of a row of `_PERSON` (never added to a session: read only)."""
    return User(id=row.id, name=row.name, role=row.role, token_hash=row.token_hash, active=row.active,
                created_at=row.created_at)


def authenticate(engine: Engine, method: str, bearer: str | None, cookie: str | None, csrf: str | None) -> Principal:
    """The acting user of a request; raises 401 (who are you) or 403 (CSRF)."""
    with engine.connect() as c:
        if bearer:
            row = c.execute(_BY_TOKEN, {"token_hash": hash_token(bearer)}).first()
            if row is None or not row.active:
                raise Unauthorized("unknown or disabled token")
            return Principal(_person(row), None)
        if not cookie:
            raise Unauthorized("sign in first")
        row = c.execute(_BY_SESSION, {"id_hash": hash_token(cookie)}).first()
    if row is None or row.session_expires_at <= now():
        raise Unauthorized("session expired; sign in again")
    if row.id is None or not row.active:
        raise Unauthorized("account disabled")
    if method not in SAFE_METHODS and not (csrf and hmac.compare_digest(csrf, row.csrf)):
        raise Forbidden("missing or wrong CSRF token (X-CSRF-Token)")
    return Principal(_person(row), row.csrf)
