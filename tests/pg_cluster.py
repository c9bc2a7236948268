"""A throw-away PostgreSQL cluster for the suite: ``initdb`` in a temp dir, ``pg_ctl start`` on a free loopback
port, one fresh database per test, stopped at the end. Debian's ``postgresql`` package provides the binaries
(`make test` installs it). PostgreSQL refuses to run as root, so as root the cluster runs as the ``postgres`` user
that package creates."""

from __future__ import annotations

import contextlib
import fcntl
import glob
import json
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path

import psycopg


def _binaries() -> Path | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"), key=lambda p: int(p.split("/")[4]))
    if found:
        return Path(found[-1]).parent
    initdb = shutil.which("initdb")
    return Path(initdb).resolve().parent if initdb else None


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class PostgresCluster:
    def __init__(self, folder: Path | None = None, port: int | None = None) -> None:
        """A new cluster's place (``start`` makes it), or with ``folder`` and ``port`` a running one's."""
        bindir = _binaries()
        if bindir is None:
            raise RuntimeError("PostgreSQL is missing: `make test` installs it (apt-get install postgresql)")
        self.bindir = bindir
        self.folder = folder or Path(tempfile.mkdtemp(prefix="drivebench-pg-"))
        self.data = self.folder / "data"
        self.port = port or _free_port()
        self._user = "postgres" if os.geteuid() == 0 else None

    def _run(self, *args: str) -> None:
        command = [str(self.bindir / args[0]), *args[1:]]
        if self._user:
            command = ["runuser", "-u", self._user, "--", *command]
        done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
        if done.returncode:
            raise RuntimeError(f"{' '.join(args[:2])} failed ({done.returncode}): {done.stderr or done.stdout}")

    def start(self) -> PostgresCluster:
        if self._user:
            entry = pwd.getpwnam(self._user)
            os.chown(self.folder, entry.pw_uid, entry.pw_gid)
        self._run("initdb", "-D", str(self.data), "-U", "postgres", "--auth=trust", "-E", "UTF8", "--no-sync")
        options = (f"-p {self.port} -c listen_addresses=127.0.0.1 -k {self.folder} -c fsync=off "
                   "-c synchronous_commit=off -c full_page_writes=off -c max_connections=200")
        self._run("pg_ctl", "-D", str(self.data), "-o", options, "-l", str(self.folder / "log"), "-w",
                  "-t", "60", "start")
        return self

    def stop(self) -> None:
        try:
            self._run("pg_ctl", "-D", str(self.data), "-m", "immediate", "-w", "stop")
        finally:
            shutil.rmtree(self.folder, ignore_errors=True)

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{database}"

    def new_database(self) -> str:
        """A fresh, empty database; its SQLAlchemy URL."""
        name = f"t_{uuid.uuid4().hex[:16]}"
        with psycopg.connect(f"host=127.0.0.1 port={self.port} user=postgres dbname=postgres",
                             autocommit=True) as connection:
            connection.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)

    def drop_database(self, url: str) -> None:
        name = url.rsplit("/", 1)[1]
        with psycopg.connect(f"host=127.0.0.1 port={self.port} user=postgres dbname=postgres",
                             autocommit=True) as connection:
            connection.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    with path.open("a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@contextlib.contextmanager
def shared_cluster(folder: Path) -> Iterator[PostgresCluster]:
    """One cluster for the processes of a run (pytest-xdist workers) that share ``folder``: the first to come
    starts it, the last to leave stops it (a count in ``folder``/cluster.json, under a file lock). Each worker
    starting its own cluster cost each an initdb at the same time, which a loaded machine did not finish within
    a test's timeout."""
    lock, state = folder / "cluster.lock", folder / "cluster.json"
    with _locked(lock):
        if state.exists():
            known = json.loads(state.read_text())
            cluster = PostgresCluster(Path(known["folder"]), int(known["port"]))
            known["users"] += 1
        else:
            cluster = PostgresCluster().start()
            known = {"folder": str(cluster.folder), "port": cluster.port, "users": 1}
        state.write_text(json.dumps(known))
    try:
        yield cluster
    finally:
        with _locked(lock):
            known = json.loads(state.read_text())
            known["users"] -= 1
            if known["users"]:
                state.write_text(json.dumps(known))
            else:
                state.unlink()
                cluster.stop()
