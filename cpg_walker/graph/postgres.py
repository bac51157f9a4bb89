"""A throwaway PostgreSQL server for tests, benchmarks and CI on this machine (Optuna's RDB storage for
workers on several "hosts": graph/netns.py's Spokes). Every client is trusted (no password; ``allow`` opens
TCP to whole subnets): never for data that matters, nor on a network others share.

    with PostgresServer(listen=("127.0.0.1", "10.232.0.1")) as pg:
        optuna.create_study(storage=pg.url(), study_name="s")   # postgresql+psycopg://postgres@127.0.0.1:P/cpg_walker

The binaries are looked up on PATH, then in /usr/lib/postgresql/*/bin (newest first). PostgreSQL refuses to
run as root, so as root the server runs as the ``postgres`` account (else ``nobody``), which owns its
directory; as another user, as that user. The directory, ``/tmp/cpgw-pg-<pid>-*`` after the creating
process, holds the cluster (``data/``), the Unix socket and the log (``server.log``). Entering a server
first stops and deletes those of processes that are gone (a crashed run); leaving it always stops it
(``pg_ctl stop -m fast``) and deletes its directory.
"""

from __future__ import annotations

import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from cpg_walker.graph.netns import process_alive

#: Where the servers' directories go, and the start of their names (``<STALE_PREFIX><pid>-<random>``).
ROOT = Path("/tmp")
STALE_PREFIX = "cpgw-pg-"
#: The programs needed, all from one directory.
TOOLS = ("initdb", "pg_ctl", "postgres", "createdb")
#: The database created, and the superuser role clients connect as.
DATABASE = "cpg_walker"
ROLE = "postgres"
#: Accounts tried, in order, to run the server when we are root.
ACCOUNTS = ("postgres", "nobody")
#: Wall s that pg_ctl waits for the server to start or stop.
PG_CTL_TIMEOUT_S = 60
#: Settings appended to postgresql.conf: crash safety off (a server that loses its data on a power cut
#: is fine here, and commits no longer wait for the disk), the default connection limit.
SETTINGS = {"fsync": "off", "synchronous_commit": "off", "full_page_writes": "off", "max_connections": "100"}


def bin_dir() -> Path | None:
    """The directory holding all of ``TOOLS``: pg_ctl's on PATH (its real one, symlinks resolved), else
    the newest /usr/lib/postgresql/<version>/bin; None when there is none."""
    candidates = []
    on_path = shutil.which("pg_ctl")
    if on_path:
        candidates += [Path(os.path.realpath(on_path)).parent, Path(on_path).parent]

    def version(d: Path) -> tuple[int, ...]:
        v = d.parent.name
        return tuple(int(p) for p in v.split(".")) if v.replace(".", "").isdigit() else (-1,)

    candidates += sorted(Path("/usr/lib/postgresql").glob("*/bin"), key=version, reverse=True)
    for d in candidates:
        if all(os.access(d / t, os.X_OK) and (d / t).is_file() for t in TOOLS):
            return d
    return None


def account() -> pwd.struct_passwd | None:
    """The account the server runs as: ours when we are not root, else the first of ``ACCOUNTS`` that
    exists and is not root; None when there is none."""
    if os.geteuid() != 0:
        return pwd.getpwuid(os.geteuid())
    for name in ACCOUNTS:
        try:
            pw = pwd.getpwnam(name)
        except KeyError:
            continue
        if pw.pw_uid != 0:
            return pw
    return None


def unavailable() -> str | None:
    """Why a server cannot be started here (no binaries, no unprivileged account to run it as), or None."""
    if bin_dir() is None:
        return f"PostgreSQL's {', '.join(TOOLS)} not found on PATH nor in /usr/lib/postgresql/*/bin"
    if account() is None:
        return f"running as root, and none of the accounts {', '.join(ACCOUNTS)} exists to run PostgreSQL as"
    if not ROOT.is_dir():
        return f"{ROOT} does not exist"
    return None


def _env() -> dict[str, str]:
    """Our environment without libpq's PG* variables (a PGDATA or PGPORT of the caller must not steer the
    tools), in the C locale."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PG")}
    env["LC_ALL"] = "C"
    return env


def _run_as(pw: pwd.struct_passwd, args: list[str], timeout: float, **kwargs) -> subprocess.CompletedProcess:
    """Run ``args`` as ``pw`` (switching user only when we are root; no supplementary groups), capturing
    output; CalledProcessError on failure."""
    switch = {"user": pw.pw_uid, "group": pw.pw_gid, "extra_groups": []} if os.geteuid() == 0 else {}
    return subprocess.run(args, check=True, capture_output=True, text=True, timeout=timeout, env=_env(),
                          **switch, **kwargs)


def _stop(directory: Path, mode: str = "fast") -> None:
    """Stop the server of ``directory`` if one runs there (``pg_ctl stop -m mode``, as the owner of its
    data directory); quiet when none does."""
    data, tools = directory / "data", bin_dir()
    if not (data / "postmaster.pid").exists() or tools is None:
        return
    try:
        owner = pwd.getpwuid(data.stat().st_uid)
        _run_as(owner, [str(tools / "pg_ctl"), "stop", "-D", str(data), "-m", mode, "-w",
                        "-t", str(PG_CTL_TIMEOUT_S)], timeout=PG_CTL_TIMEOUT_S + 10, cwd=directory)
    except (KeyError, OSError, subprocess.SubprocessError):
        if mode != "immediate":
            _stop(directory, "immediate")


def remove_stale() -> list[Path]:
    """Stop the servers of this module whose creating process is gone and delete their directories; the
    directories."""
    gone = []
    for d in ROOT.glob(f"{STALE_PREFIX}*"):
        pid = d.name[len(STALE_PREFIX):].split("-")[0]
        if d.is_dir() and pid.isdigit() and not process_alive(int(pid)):
            _stop(d, "immediate")
            shutil.rmtree(d, ignore_errors=True)
            gone.append(d)
    return gone


def free_port() -> int:
    """A TCP port free on every address right now (the kernel's pick)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("", 0))
        return s.getsockname()[1]


def _reachable(address: str, port: int) -> bool:
    """A TCP connection to (address, port) is accepted; a wildcard address is tried on loopback."""
    address = {"*": "127.0.0.1", "0.0.0.0": "127.0.0.1", "::": "::1"}.get(address, address)
    try:
        with socket.create_connection((address, port), timeout=5):
            return True
    except OSError:
        return False


class PostgresServer:
    """Context manager: a fresh cluster (``initdb``) in its own directory under /tmp, serving TCP on
    ``port`` (None: a free one) at the ``listen`` addresses (all of which must exist: the gateways of
    Spokes, say, are made first), trusting every local client and any TCP client from 127.0.0.1, ::1 and
    the ``allow`` subnets, with the database ``database``; yields itself, started. ``startup_s`` and
    ``shutdown_s``: the wall s entering and leaving took."""

    def __init__(self, listen: Sequence[str] = ("127.0.0.1",), port: int | None = None,
                 allow: Sequence[str] = ("10.0.0.0/8",), database: str = DATABASE):
        if not listen:
            raise ValueError("PostgresServer needs at least one listen address")
        self.listen, self.allow, self.database = tuple(listen), tuple(allow), database
        self._fixed_port = port
        self.port = port or 0
        self.dir: Path | None = None
        self.startup_s = self.shutdown_s = float("nan")

    @property
    def data(self) -> Path:
        """The cluster's data directory."""
        if self.dir is None:
            raise RuntimeError("the server is not started")
        return self.dir / "data"

    @property
    def log(self) -> Path:
        """The server's log file."""
        return self.data.parent / "server.log"

    def url(self, host: str | None = None, driver: str | None = "psycopg") -> str:
        """The SQLAlchemy URL of the database (what Optuna's storage takes), reached at ``host`` (default:
        the first listen address, loopback for a wildcard): ``postgresql+psycopg://postgres@HOST:PORT/DB``;
        ``driver=None`` gives the libpq URI ``postgresql://...`` (``psycopg.connect``, psql)."""
        host = host or {"*": "127.0.0.1", "0.0.0.0": "127.0.0.1", "::": "::1"}.get(self.listen[0],
                                                                                  self.listen[0])
        if ":" in host:
            host = f"[{host}]"
        scheme = f"postgresql+{driver}" if driver else "postgresql"
        return f"{scheme}://{ROLE}@{host}:{self.port}/{self.database}"

    def __enter__(self) -> PostgresServer:
        why = unavailable()
        if why is not None:
            raise RuntimeError(f"cannot start PostgreSQL: {why}")
        start = time.monotonic()
        remove_stale()
        try:
            self._start()
        except BaseException:
            self._remove()
            raise
        self.startup_s = time.monotonic() - start
        return self

    def _start(self) -> None:
        tools, pw = bin_dir(), account()
        assert tools is not None and pw is not None
        self.dir = Path(tempfile.mkdtemp(prefix=f"{STALE_PREFIX}{os.getpid()}-", dir=ROOT))
        self.dir.chmod(0o755)  # the socket usable by any local user; data/ itself stays 0700
        if os.geteuid() == 0:
            os.chown(self.dir, pw.pw_uid, pw.pw_gid)
        _run_as(pw, [str(tools / "initdb"), "-D", str(self.data), f"--username={ROLE}", "--auth=trust",
                     "--encoding=UTF8", "--locale=C", "--no-sync", "--no-instructions"],
                timeout=PG_CTL_TIMEOUT_S, cwd=self.dir)
        with open(self.data / "pg_hba.conf", "a") as hba:
            hba.write("\n# cpg_walker throwaway test server: every client of these subnets is trusted\n")
            for net in self.allow:
                hba.write(f"host all all {net} trust\n")
        settings = {**SETTINGS, "listen_addresses": f"'{','.join(self.listen)}'",
                    "unix_socket_directories": f"'{self.dir}'"}
        with open(self.data / "postgresql.conf", "a") as conf:
            conf.write("\n# cpg_walker throwaway test server\n")
            conf.writelines(f"{k} = {v}\n" for k, v in settings.items())
        for attempt in range(3):
            self.port = self._fixed_port or free_port()
            try:
                _run_as(pw, [str(tools / "pg_ctl"), "start", "-D", str(self.data), "-l", str(self.log),
                             "-o", f"-p {self.port}", "-w", "-t", str(PG_CTL_TIMEOUT_S), "-s"],
                        timeout=PG_CTL_TIMEOUT_S + 10, cwd=self.dir, start_new_session=True)
                break
            except subprocess.CalledProcessError as exc:
                log = self.log.read_text(errors="replace") if self.log.exists() else ""
                if self._fixed_port is None and "already in use" in log and attempt < 2:
                    self.log.unlink()  # another process took the port between our pick and the bind
                    continue
                raise RuntimeError(f"PostgreSQL did not start ({exc.stderr.strip()}); its log:\n"
                                   f"{log[-3000:]}") from exc
        missing = [a for a in self.listen if not _reachable(a, self.port)]
        if missing:
            raise RuntimeError(f"PostgreSQL does not accept TCP at {missing} port {self.port}; its log:\n"
                               f"{self.log.read_text(errors='replace')[-3000:]}")
        _run_as(pw, [str(tools / "createdb"), "-h", str(self.dir), "-p", str(self.port), "-U", ROLE,
                     self.database], timeout=PG_CTL_TIMEOUT_S, cwd=self.dir)

    def _remove(self) -> None:
        if self.dir is None:
            return
        try:
            _stop(self.dir)
        finally:
            shutil.rmtree(self.dir, ignore_errors=True)

    def __exit__(self, *exc) -> None:
        start = time.monotonic()
        self._remove()
        self.shutdown_s = time.monotonic() - start
