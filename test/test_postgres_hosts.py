"""Workers on several "hosts" sharing one PostgreSQL (the ground of Optuna studies run by workers in network
namespaces): a throwaway server (graph/postgres.py) in the root namespace, listening on the gateways of
two spokes (graph/netns.py: a namespace each, joined to the root namespace by a veth pair of its own); a
process in each namespace writes to it across its link, and an Optuna study runs from one namespace. Also:
everything is gone after the ``with`` blocks, and a crashed run's server and namespaces are removed by
the next run. Root, ``ip netns`` and PostgreSQL needed, else skipped."""

from __future__ import annotations

import importlib.util
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from cpg_walker.graph import netns, postgres

WHY_NOT = postgres.unavailable() or netns.unavailable()
pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(WHY_NOT is not None, reason=f"needs PostgreSQL and namespaces: {WHY_NOT}")]

#: Run in a namespace: insert a row naming it (argv: the namespace; stdin: the libpq URI, once the server is
#: up: the workers start with the server, so that their imports overlap its initdb).
INSERT = """
import sys, psycopg
with psycopg.connect(sys.stdin.readline().strip(), connect_timeout=10) as conn:
    conn.execute("INSERT INTO hosts VALUES (%s, inet_client_addr())", (sys.argv[1],))
"""
#: Run in a namespace: an Optuna study of two trials in the server (argv: study name; stdin: SQLAlchemy URL).
OPTIMIZE = """
import sys, optuna
storage = optuna.storages.RDBStorage(sys.stdin.readline().strip())
study = optuna.create_study(storage=storage, study_name=sys.argv[1])
study.optimize(lambda t: t.suggest_float("x", 0, 1), n_trials=2)
"""


def _env() -> dict[str, str]:
    """Ours, with this checkout first on PYTHONPATH (``ip netns exec`` keeps the environment)."""
    root = str(Path(__file__).resolve().parent.parent)
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)}


def _in(spoke: netns.Spoke, code: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen([*spoke.prefix(), sys.executable, "-c", code, *args], env=_env(),
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _finish(proc: subprocess.Popen) -> None:
    """Wait until the worker has done its work (it has been handed the URL)."""
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, f"{proc.args[:4]} failed ({proc.returncode}):\n{out}\n{err[-2000:]}"


def _left(names: list[str], dirs: list[Path]) -> list[str]:
    """What of these namespaces/devices, server directories and their postgres processes still exists."""
    netns_list = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    links = subprocess.run(["ip", "-o", "link", "show"], capture_output=True, text=True).stdout
    procs = subprocess.run(["ps", "-eo", "args"], capture_output=True, text=True).stdout
    return ([n for n in names if re.search(rf"(^|\s){re.escape(n)}[\s@:]", netns_list + "\n" + links)]
            + [str(d) for d in dirs if d.exists() or str(d) in procs])


def test_workers_in_namespaces_share_postgres():
    psycopg = pytest.importorskip("psycopg")
    if importlib.util.find_spec("optuna") is None:  # not imported here: the workers use it
        pytest.skip("optuna is not installed")

    with netns.Spokes(2) as spokes:
        assert len({s.gateway for s in spokes}) == 2 and all(s.address != s.gateway for s in spokes)
        # (where, driver of its URL: None, libpq's for psycopg; Optuna's SQLAlchemy needs "psycopg")
        workers = [(s, None, _in(s, INSERT, s.netns)) for s in spokes]
        workers.append((spokes[0], "psycopg", _in(spokes[0], OPTIMIZE, "across")))
        try:
            with postgres.PostgresServer(listen=("127.0.0.1", *(s.gateway for s in spokes))) as server:
                with psycopg.connect(server.url(driver=None)) as conn:  # (at once, two would race)
                    conn.execute("CREATE TABLE hosts (netns text PRIMARY KEY, addr inet)")
                for spoke, driver, w in workers:  # all at once: they share the server
                    w.stdin.write(server.url(spoke.gateway, driver=driver) + "\n")
                    w.stdin.flush()
                for _, _, w in workers:
                    _finish(w)
                with psycopg.connect(server.url(driver=None)) as conn:
                    rows = dict(conn.execute("SELECT netns, host(addr) FROM hosts").fetchall())
                    # Optuna's own tables (studies, trials: state by name)
                    trials = conn.execute("SELECT t.state FROM trials t JOIN studies s USING (study_id) "
                                          "WHERE s.study_name = 'across'").fetchall()
                    xs = [x for (x,) in conn.execute("SELECT param_value FROM trial_params")]
        finally:  # none may outlive its namespace (it would keep it, and its link, alive)
            for _, _, w in workers:
                if w.poll() is None:
                    w.kill()
                    w.communicate()
        # each row came across its own link: from its namespace's address
        assert rows == {s.netns: s.address for s in spokes}
        assert trials == [("COMPLETE",)] * 2
        assert len(xs) == 2 and all(0 <= x <= 1 for x in xs)
        names = [n for s in spokes for n in (s.netns, s.root_device)]
    assert not _left(names, [server.dir])


def test_a_crashed_runs_server_and_namespaces_are_removed():
    code = ("import os\nfrom cpg_walker.graph import netns, postgres\n"
            "(s,) = netns.Spokes(1).__enter__()\n"
            "pg = postgres.PostgresServer(listen=(s.gateway,)).__enter__()\n"
            "print(s.netns, s.root_device, pg.dir, flush=True)\n"
            "os.kill(os.getpid(), 9)\n")
    proc = subprocess.Popen([sys.executable, "-c", code], env=_env(), stdout=subprocess.PIPE, text=True)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, out
    ns, root_device, directory = out.split()
    assert _left([ns, root_device], [Path(directory)]) == [ns, root_device, directory]  # left running
    # what the next run does on entering its own
    assert ns in netns.remove_stale()  # its root-side veth end goes with it (or is deleted by name)
    assert Path(directory) in postgres.remove_stale()
    assert not _left([ns, root_device], [Path(directory)])
