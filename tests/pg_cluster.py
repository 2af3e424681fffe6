"""A throwaway PostgreSQL server for tests and benchmarks: Debian's `postgresql` binaries,
a cluster in a temp folder, listening on a unix socket in that folder only (no TCP port),
removed on exit.

PostgreSQL refuses to run as root (CI runs as root): the cluster then belongs to `nobody`
and its programs run as that user; otherwise as the current user. Durability is traded for
speed (fsync off): the data is thrown away anyway.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import subprocess
import tempfile
import time
import uuid
from pathlib import Path

PG_BINS = sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=lambda p: int(p.split("/")[-2]))
MISSING = ("PostgreSQL server binaries not found under /usr/lib/postgresql/*/bin: install Debian's "
           "`postgresql` package (`WITH_POSTGRES=1 bash scripts/setup.sh`, part of `make setup-test`)")


class PgCluster:
    """`with PgCluster() as pg: url = pg.new_database()`."""

    def __init__(self, max_connections: int = 300):
        if not PG_BINS:
            raise RuntimeError(MISSING)
        self.bin = Path(PG_BINS[-1])
        self.max_connections = max_connections
        self.proc: subprocess.Popen | None = None
        self.root: Path | None = None

    def _as_owner(self) -> dict:
        if os.geteuid() != 0:
            return {}
        nobody = pwd.getpwnam("nobody")
        return {"user": nobody.pw_uid, "group": nobody.pw_gid, "extra_groups": []}

    def __enter__(self) -> PgCluster:
        # a short path: a unix socket's path is limited to ~100 characters
        self.root = Path(tempfile.mkdtemp(prefix="pg-", dir="/tmp"))
        data, self.socket_dir = self.root / "data", self.root
        owner = self._as_owner()
        if owner:
            os.chown(self.root, owner["user"], owner["group"])
        os.chmod(self.root, 0o700)
        env = {"PATH": os.environ.get("PATH", ""), "LANG": "C.UTF-8", "LC_ALL": "C.UTF-8"}
        out = subprocess.run([str(self.bin / "initdb"), "-D", str(data), "-U", "postgres", "--auth=trust",
                              "-E", "UTF8", "--no-sync", "--no-instructions"], capture_output=True, text=True,
                             env=env, cwd=self.root, timeout=120, **owner)
        if out.returncode != 0:
            raise RuntimeError(f"initdb failed: {out.stderr[-2000:]}")
        self.log = self.root / "postgres.log"
        self.proc = subprocess.Popen(
            [str(self.bin / "postgres"), "-D", str(data), "-k", str(self.socket_dir), "-c", "listen_addresses=",
             "-c", f"max_connections={self.max_connections}", "-c", "fsync=off", "-c", "synchronous_commit=off",
             "-c", "full_page_writes=off", "-c", "shared_buffers=64MB"],
            stdout=subprocess.DEVNULL, stderr=open(self.log, "wb"), env=env, cwd=self.root, **owner)
        deadline = time.monotonic() + 30
        while not (self.socket_dir / ".s.PGSQL.5432").exists():
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.__exit__(None, None, None)
                raise RuntimeError(f"postgres did not start: {self.log.read_text()[-2000:] if self.log.exists() else ''}")
            time.sleep(0.05)
        self._admin("SELECT 1")  # accepting connections, not only listening
        return self

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://postgres@/{database}?host={self.socket_dir}"

    def _admin(self, sql: str) -> None:
        import psycopg

        deadline = time.monotonic() + 30
        while True:
            try:
                with psycopg.connect(f"host={self.socket_dir} user=postgres dbname=postgres", autocommit=True) as c:
                    c.execute(sql)
                return
            except psycopg.OperationalError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    def new_database(self) -> str:
        name = "t_" + uuid.uuid4().hex[:12]
        self._admin(f"CREATE DATABASE {name}")
        return self.url(name)

    def drop_database(self, url: str) -> None:
        from sqlalchemy.engine import make_url

        self._admin(f"DROP DATABASE IF EXISTS {make_url(url).database} WITH (FORCE)")

    def __exit__(self, *exc) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(2)  # SIGINT: fast shutdown
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.root is not None:
            shutil.rmtree(self.root, ignore_errors=True)
