"""The engine across hosts, on this machine: `cpg-walker scaleout --out DIR` and the ``studies`` benchmark.

"Hosts" are network namespaces joined to the root namespace by veth pairs (graph/netns.py ``Spokes``); a
throwaway PostgreSQL server (graph/postgres.py) listens in the root namespace on the links' root ends;
one ``cpg-walker worker --jobs 1`` runs in each namespace and reaches the database over its link; the
coordinator (the experiment's own command, ``--jobs 0``) runs in the root namespace and walks nothing.

``scaleout`` runs, in order, and writes DIR/scaleout.json and scaleout.md:

1. the sweep on one machine (the default SQLite study, ``jobs`` local workers) — the reference tables;
2. the same sweep through PostgreSQL with worker A alone, then with A and B: the trials each ran, trials
   per hour over the span from the first trial's start to the last one's end, and both sweep.json
   compared with the reference;
3. the feedback search (same seed) on one machine, then through PostgreSQL with A and B, B killed
   (SIGKILL, its whole process group) in the middle of a trial once it has finished one: the trial lost,
   its retry and who ran it, and the search's trials.jsonl / best.yaml compared with the reference;
4. optuna-dashboard on the PostgreSQL studies, screenshot by headless Chromium (DIR/dashboard.png).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from cpg_walker.experiments.study import EngineSettings, open_storage

#: Heartbeat and grace period of the scaled-out studies: a killed worker's trial is enqueued again
#: ``GRACE_S`` after its last heartbeat (config/study.yaml's are for long real runs).
HEARTBEAT_S, GRACE_S = 2.0, 10.0
#: Wall s a worker waits for its study to be created.
WORKER_WAIT_S = 300.0
#: The studies of the scaled-out runs (and their output directories).
RUNS = ("sweep-1-worker", "sweep-2-workers", "search-2-workers")


def unavailable() -> str | None:
    """Why the namespaces or the server cannot be made here (None: they can)."""
    from cpg_walker.graph import netns, postgres

    return netns.unavailable() or postgres.unavailable()


@contextmanager
def cluster(n: int):
    """A PostgreSQL server and ``n`` namespaces that reach it: yields (server, spokes)."""
    from cpg_walker.graph.netns import Spokes
    from cpg_walker.graph.postgres import PostgresServer

    with ExitStack() as stack:
        spokes = stack.enter_context(Spokes(n))
        server = stack.enter_context(PostgresServer(listen=("127.0.0.1", *(s.gateway for s in spokes))))
        yield server, spokes


def _package_env() -> dict[str, str]:
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def start_worker(spoke, server, study: str, name: str, log: Path, jobs: int = 1) -> subprocess.Popen:
    """``cpg-walker worker`` inside ``spoke``'s namespace, on ``study`` of ``server`` reached at the spoke's
    gateway (its own session: killing its group kills every process of it); output to ``log``."""
    cmd = [*spoke.prefix(), sys.executable, "-m", "cpg_walker.cli.main", "worker",
           "--storage", server.url(host=spoke.gateway), "--study", study, "--jobs", str(jobs),
           "--name", name, "--wait", str(WORKER_WAIT_S)]
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("w") as fh:
        return subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, env=_package_env(),
                                start_new_session=True)


def stop_workers(procs: list[subprocess.Popen], timeout: float = 60.0) -> list[int | None]:
    """Wait for the workers to exit (they do once their study is finished); kill what is left. Their exit
    statuses (None: had to be killed)."""
    end = time.monotonic() + timeout
    codes: list[int | None] = []
    for p in procs:
        try:
            codes.append(p.wait(timeout=max(0.1, end - time.monotonic())))
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
            codes.append(None)
    return codes


class Killer(threading.Thread):
    """Kills worker ``name`` (its process group) in the middle of a trial once it has finished
    ``after_complete`` trials and its current one has run ``into_s`` wall s; records which trial."""

    def __init__(self, url: str, study: str, name: str, proc: subprocess.Popen, after_complete: int = 1,
                 into_s: float = 0.2):
        super().__init__(daemon=True)
        self.url, self.study, self.name, self.proc = url, study, name, proc
        self.after_complete, self.into_s = after_complete, into_s
        self.killed: dict[str, Any] | None = None
        self._halt = threading.Event()

    def stop(self) -> None:
        self._halt.set()

    def run(self) -> None:
        import datetime

        import optuna
        from optuna.trial import TrialState

        storage = open_storage(self.url)
        while not self._halt.is_set() and self.proc.poll() is None:
            try:
                trials = optuna.load_study(study_name=self.study, storage=storage).get_trials(deepcopy=False)
            except KeyError:  # not created yet
                time.sleep(0.2)
                continue
            mine = [t for t in trials if t.user_attrs.get("worker") == self.name]
            done = sum(t.state == TrialState.COMPLETE for t in mine)
            now = datetime.datetime.now()
            running = [t for t in mine if t.state == TrialState.RUNNING and t.datetime_start is not None
                       and (now - t.datetime_start).total_seconds() >= self.into_s]
            if done >= self.after_complete and running:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
                self.killed = {"worker": self.name, "trial": running[0].number,
                               "batch": running[0].user_attrs.get("batch"),
                               "index": running[0].user_attrs.get("index"),
                               "its_completed_trials_before": done,
                               "killed_at": now.isoformat(timespec="seconds")}
                return
            time.sleep(0.1)


def study_summary(url: str, name: str) -> dict:
    """Who ran what in a study: per worker the trials completed; the trials failed and their retries;
    trials per hour over the span of the completed trials."""
    import optuna
    from optuna.trial import TrialState

    trials = optuna.load_study(study_name=name, storage=open_storage(url)).get_trials(deepcopy=False)
    done = [t for t in trials if t.state == TrialState.COMPLETE]
    per: dict[str, int] = {}
    for t in done:
        per[t.user_attrs.get("worker", "?")] = per.get(t.user_attrs.get("worker", "?"), 0) + 1
    failed = [t for t in trials if t.state == TrialState.FAIL]
    retries = []
    for f in failed:
        again = [t for t in trials if f.number in t.system_attrs.get("retry_history", [])]
        retries.append({"trial": f.number, "worker": f.user_attrs.get("worker"),
                        "batch": f.user_attrs.get("batch"), "index": f.user_attrs.get("index"),
                        "error": f.user_attrs.get("error"),
                        "retried_as": [{"trial": t.number, "state": t.state.name,
                                        "worker": t.user_attrs.get("worker")} for t in again]})
    span = 0.0
    if done:
        span = (max(t.datetime_complete for t in done) - min(t.datetime_start for t in done)).total_seconds()
    return {"study": name, "trials": len(trials), "completed": len(done), "by_worker": per,
            "failed": retries, "span_s": round(span, 2),
            "trials_per_hour": round(3600.0 * len(done) / span, 1) if span > 0 else None}


def _same_json(a: Path, b: Path, drop: tuple[str, ...] = ()) -> bool:
    x, y = (json.loads(p.read_text()) for p in (a, b))
    for k in drop:
        x.pop(k, None)
        y.pop(k, None)
    return x == y


def compare_sweeps(reference: Path, other: Path) -> dict:
    """sweep.json and transitions.json of two sweep directories: identical or not (the provenance of
    transitions.json aside)."""
    return {"sweep.json": _same_json(reference / "sweep.json", other / "sweep.json"),
            "transitions.json": _same_json(reference / "transitions.json", other / "transitions.json",
                                           ("provenance",))}


def compare_searches(reference: Path, other: Path) -> dict:
    """trials.jsonl and best.yaml of two feedback-search directories: identical or not."""
    return {f: (reference / f).read_text() == (other / f).read_text() for f in ("trials.jsonl", "best.yaml")}


def run_with_workers(spokes, server, study: str, names: list[str], logs: Path, coordinate,
                     kill: str | None = None) -> dict:
    """Start a worker per name (the k-th in the k-th spoke), run ``coordinate(url)`` in this process
    (``url``: the server's, from the root namespace), optionally kill worker ``kill`` mid-trial; the
    study's summary, the wall time and the workers' exit statuses."""
    url = server.url()
    open_storage(url)  # Optuna's tables, before the workers race to make them
    procs = [start_worker(s, server, study, n, logs / f"worker_{n}.log") for s, n in zip(spokes, names,
                                                                                        strict=False)]
    killer = None
    if kill is not None:
        killer = Killer(url, study, kill, procs[names.index(kill)])
        killer.start()
    t0 = time.monotonic()
    try:
        coordinate(url)
    finally:
        wall = time.monotonic() - t0
        if killer is not None:
            killer.stop()
            killer.join(timeout=10)
        codes = stop_workers(procs)
    out = {**study_summary(url, study), "wall_s": round(wall, 2), "worker_exit": dict(zip(names, codes,
                                                                                          strict=False))}
    if killer is not None:
        out["killed"] = killer.killed
    return out


def _settings() -> EngineSettings:
    return EngineSettings.load(heartbeat_interval_s=HEARTBEAT_S, grace_period_s=GRACE_S)


def run_scaleout(out_dir: str | Path, quick: bool = True, jobs: int = 2, sweep_config: str | None = None,
                 search_config: str | None = None, generations: int | None = None, seed: int = 1,
                 screenshot: bool = True, log=print) -> dict:
    """Everything of the module docstring; returns the report (also DIR/scaleout.json, scaleout.md)."""
    from cpg_walker.experiments.feedback_search import search
    from cpg_walker.experiments.sweep import run_sweep

    why = unavailable()
    if why:
        raise RuntimeError(f"scaleout needs network namespaces and PostgreSQL: {why}")
    out = Path(out_dir)
    for sub in ("local_sweep", "local_search", *RUNS, "logs"):
        shutil.rmtree(out / sub, ignore_errors=True)  # this command's own outputs of an earlier run
    out.mkdir(parents=True, exist_ok=True)
    settings = _settings()
    quiet = {"log": lambda s: None}
    report: dict[str, Any] = {"quick": quick, "seed": seed, "heartbeat_s": HEARTBEAT_S, "grace_s": GRACE_S}

    log("scaleout: the sweep on one machine (the reference)")
    t0 = time.monotonic()
    run_sweep(out / "local_sweep", quick=quick, jobs=jobs, config=sweep_config, progress_enabled=False)
    local_sweep_s = time.monotonic() - t0
    log("scaleout: the feedback search on one machine (the reference)")
    search(out / "local_search", generations=generations, seed=seed, jobs=jobs, quick=quick,
           config=search_config, **quiet)
    with cluster(2) as (server, spokes):
        report["hosts"] = [{"netns": s.netns, "address": s.address, "gateway": s.gateway} for s in spokes]
        runs: dict[str, Any] = {}
        for study, names in (("sweep-1-worker", ["A"]), ("sweep-2-workers", ["A", "B"])):
            log(f"scaleout: the sweep through PostgreSQL, worker(s) {', '.join(names)}")
            d = out / study

            def coordinate(url: str, d: Path = d, study: str = study) -> None:
                run_sweep(d, quick=quick, jobs=0, config=sweep_config, progress_enabled=False, storage=url,
                          study=study, settings=settings)

            runs[study] = run_with_workers(spokes, server, study, names, out / "logs" / study, coordinate)
            runs[study]["same_as_one_machine"] = compare_sweeps(out / "local_sweep", d)
        log("scaleout: the feedback search through PostgreSQL, workers A and B, B killed mid-trial")
        d = out / "search-2-workers"

        def coordinate_search(url: str) -> None:
            search(d, generations=generations, seed=seed, jobs=0, quick=quick, config=search_config,
                   storage=url, study="search-2-workers", settings=settings, **quiet)

        runs["search-2-workers"] = run_with_workers(spokes, server, "search-2-workers", ["A", "B"],
                                                    out / "logs" / "search-2-workers", coordinate_search,
                                                    kill="B")
        runs["search-2-workers"]["same_as_one_machine"] = compare_searches(out / "local_search", d)
        report["runs"] = runs
        one, two = runs["sweep-1-worker"], runs["sweep-2-workers"]
        report["throughput"] = {
            "trials": one["completed"], "one_machine_wall_s": round(local_sweep_s, 2),
            "trials_per_hour_1_worker": one["trials_per_hour"],
            "trials_per_hour_2_workers": two["trials_per_hour"],
            "ratio": round(two["trials_per_hour"] / one["trials_per_hour"], 3)
            if one["trials_per_hour"] and two["trials_per_hour"] else None}
        if screenshot:
            report["dashboard"] = dashboard_screenshot(server.url(), "search-2-workers",
                                                       out / "dashboard.png")
    (out / "scaleout.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "scaleout.md").write_text(markdown(report))
    return report


def dashboard_screenshot(url: str, study: str, png: Path, port: int | None = None) -> dict:
    """optuna-dashboard on ``url`` and headless Chromium screenshots of ``study``'s page (``png``: history,
    best trial, importances, timeline) and of its trials page (``png`` with ``_trials``: a trial's
    parameters and user attributes); the pages' addresses and whether the PNGs were written (the reason
    when they were not)."""
    from cpg_walker.graph.postgres import free_port

    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    dashboard = Path(sys.executable).with_name("optuna-dashboard")
    if chromium is None or not dashboard.exists():
        return {"written": False, "why": "no chromium" if chromium is None else "no optuna-dashboard"}
    study_id = open_storage(url).get_study_id_from_name(study)
    port = port or free_port()
    page = f"http://127.0.0.1:{port}/dashboard/studies/{study_id}"
    shots = {png: page, png.with_name(png.stem + "_trials" + png.suffix): page + "/trials"}
    server = subprocess.Popen([str(dashboard), url, "--host", "127.0.0.1", "--port", str(port)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        import urllib.request

        end = time.monotonic() + 60
        while True:
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/api/studies", timeout=2).read()
                break
            except OSError:
                if time.monotonic() > end or server.poll() is not None:
                    return {"written": False, "why": "optuna-dashboard did not answer", "page": page}
                time.sleep(0.3)
        for path, address in shots.items():
            path.unlink(missing_ok=True)
            subprocess.run([chromium, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                            "--window-size=1600,1400", "--virtual-time-budget=15000", f"--screenshot={path}",
                            address], capture_output=True, timeout=120)
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=30)
    return {"written": all(p.is_file() for p in shots), "pngs": [p.name for p in shots],
            "pages": [a.replace(str(port), "PORT") for a in shots.values()],
            "command": "optuna-dashboard URL --port PORT"}


def markdown(r: dict) -> str:
    t = r["throughput"]
    lines = ["# cpg-walker scaleout: the engine across two namespaces and PostgreSQL", "",
             f"Workers: `cpg-walker worker --jobs 1` in two network namespaces (veth to the root namespace), "
             f"PostgreSQL in the root namespace; heartbeat {r['heartbeat_s']:g} s, grace {r['grace_s']:g} s. "
             f"{'Quick' if r['quick'] else 'Full'} sweep and search, seed {r['seed']}.", "",
             "| run | trials completed | by worker | failed (lost) → retried as | trials/hour | wall s | "
             "tables identical to one machine |", "|---|---|---|---|---|---|---|"]
    for name, run in r["runs"].items():
        lost = "; ".join(f"#{f['trial']} ({f['worker']}) → "
                         + ", ".join(f"#{a['trial']} {a['state']} by {a['worker']}" for a in f["retried_as"])
                         for f in run["failed"]) or "none"
        same = ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in run["same_as_one_machine"].items())
        lines.append(f"| {name} | {run['completed']} | {run['by_worker']} | {lost} | "
                     f"{run['trials_per_hour']} | {run['wall_s']} | {same} |")
    lines += ["", f"Trials per hour, the same {t['trials']} sweep trials: 1 worker "
              f"{t['trials_per_hour_1_worker']}, 2 workers {t['trials_per_hour_2_workers']} "
              f"(ratio {t['ratio']}); "
              f"on one machine with its own processes the sweep took {t['one_machine_wall_s']} s.", ""]
    k = r["runs"]["search-2-workers"].get("killed")
    if k:
        lines += [f"Worker {k['worker']} was killed (SIGKILL) during trial #{k['trial']} ({k['batch']} "
                  f"#{k['index']}), after it had completed {k['its_completed_trials_before']} trial(s).", ""]
    if r.get("dashboard", {}).get("written"):
        lines += ["optuna-dashboard on the search's study (history and best so far, importances, the "
                  "timeline with the lost trial), and its trials page (a trial's gains, per-scenario "
                  "costs and worker):",
                  "", "![dashboard](dashboard.png)", "", "![trials](dashboard_trials.png)", ""]
    return "\n".join(lines)
