"""Many walks as one Optuna study: the engine of every many-walk experiment (sweep, feedback-search,
transitions, random-walks).

An experiment's coordinator (the command a user runs) puts its walks into a named study as *waiting*
trials; workers — the coordinator's own processes (``--jobs``) and ``cpg-walker worker`` on any host that
reaches the storage — take them one at a time and run them; the coordinator reads the results back from
the study, in order. Nothing but the study is shared, so the workers need no files of the coordinator.

* **Storage.** No URL: a SQLite file ``DIR/study.db`` (no server); otherwise any Optuna RDB URL
  (``postgresql://…`` is read with psycopg 3). ``optuna-dashboard URL`` shows the study as it runs.
* **A task** is a registered module-level function of ``cpg_walker.experiments`` (``@task``) and its
  argument, stored as JSON (``encode``/``decode``: dataclasses, tuples, dicts, lists, numbers, strings) in
  the trial's user attributes ``batch`` (which part of the experiment), ``index`` (its place there),
  ``fn`` and ``item``; the worker adds ``worker`` (who ran it), the task's dashboard attributes, and
  ``result`` (the function's result, JSON) or ``error``. The trial's value is the task's ``value(result)``;
  its ``params`` (e.g. the searched gains) become Optuna parameters, so the dashboard plots them.
* **Lost workers.** A running trial's worker writes a heartbeat; one older than the grace period is failed
  by the next worker or coordinator that looks and enqueued again (Optuna's
  ``RetryHeartbeatStaleTrialCallback``, at most ``max_retry`` times); a worker interrupted (Ctrl-C,
  SIGTERM) enqueues its trial again itself. So killing a worker loses at most its running trials, and a
  study resumes after every worker stopped.
* **Settings** (config/study.yaml) are written into the study when it is created (user attribute
  ``engine``); every worker that joins uses the study's.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
import os
import signal
import socket
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cpg_walker.errors import InputError

#: The default storage's file name in an experiment's output directory.
DEFAULT_DB = "study.db"
#: Tries to open a storage whose tables another process is creating at the same moment.
CREATE_ATTEMPTS = 5
#: Modules whose functions and dataclasses a study may name (a study is data, never arbitrary code).
TASK_MODULES = "cpg_walker.experiments."
DATA_MODULES = "cpg_walker."


# ------------------------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class EngineSettings:
    """config/study.yaml: heartbeats, retries, polling."""

    heartbeat_interval_s: float = 5.0
    grace_period_s: float = 30.0
    max_retry: int = 3
    poll_s: float = 0.5
    sqlite_timeout_s: float = 60.0

    @classmethod
    def load(cls, path: str | Path | None = None, **overrides: float) -> EngineSettings:
        from cpg_walker.experiments.config_file import Config
        from cpg_walker.paths import config_path

        c = Config(path or config_path("study.yaml"))
        names = {f.name for f in dataclasses.fields(cls)}
        for key, v in c.data.items():
            if key not in names:
                raise c.error((key,), f"unknown setting; known: {', '.join(sorted(names))}")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                raise c.error((key,), f"must be a positive number, got {v!r}")
        s = cls(**{**c.data, **overrides})
        if not s.grace_period_s > 2 * s.heartbeat_interval_s:
            raise c.error(("grace_period_s",), "must be more than twice heartbeat_interval_s")
        return dataclasses.replace(s, max_retry=int(s.max_retry))


def storage_url(url: str | None, out_dir: str | Path | None = None) -> str:
    """The SQLAlchemy URL of a storage: ``url`` as given (``postgresql://`` / ``postgres://`` read with
    psycopg 3), or the default SQLite file in ``out_dir``."""
    if url is None:
        if out_dir is None:
            raise InputError("a study needs a storage URL or an output directory for its file")
        return "sqlite:///" + str((Path(out_dir) / DEFAULT_DB).resolve())
    for plain in ("postgresql://", "postgres://"):
        if url.startswith(plain):
            return "postgresql+psycopg://" + url[len(plain):]
    if "://" not in url:
        raise InputError(f"--storage {url!r}: expected a database URL such as postgresql://user@host:5432/db "
                         "or sqlite:///path/study.db")
    return url


def _quiet() -> None:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
    warnings.filterwarnings("ignore", message="Heartbeat of storage is supposed")


def open_storage(url: str, settings: EngineSettings | None = None):
    """An Optuna RDBStorage on ``url`` (a SQLAlchemy URL, see ``storage_url``); with ``settings``, with
    heartbeats and the retry of lost trials."""
    import optuna

    _quiet()
    kw: dict[str, Any] = {}
    if url.startswith("sqlite"):
        timeout = settings.sqlite_timeout_s if settings else EngineSettings().sqlite_timeout_s
        kw["engine_kwargs"] = {"connect_args": {"timeout": timeout}}
    else:
        kw["engine_kwargs"] = {"pool_pre_ping": True}
    if settings is not None:
        kw.update(heartbeat_interval=max(1, round(settings.heartbeat_interval_s)),
                  grace_period=max(2, round(settings.grace_period_s)),
                  heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback(
                      max_retry=settings.max_retry))
    for attempt in range(CREATE_ATTEMPTS):
        try:
            storage = optuna.storages.RDBStorage(url, **kw)
            break
        except Exception as exc:  # a wrong URL, an unreachable server, a missing driver
            # on a new database, workers and a coordinator starting at once race to create Optuna's tables
            racing = "UniqueViolation" in str(exc) or "already exists" in str(exc)
            if not racing or attempt == CREATE_ATTEMPTS - 1:
                raise InputError(f"cannot open the study storage {redact(url)}: {type(exc).__name__}: "
                                 f"{exc}") from None
            time.sleep(0.5 * (attempt + 1))
    if url.startswith("sqlite"):
        _immediate_transactions(storage.engine)
    return storage


def _immediate_transactions(engine) -> None:
    """SQLite takes its write lock at a transaction's first write and ignores SELECT … FOR UPDATE, so two
    workers could both read a trial as waiting and both take it (seen: the same trial told twice). Every
    transaction begins IMMEDIATE instead (SQLAlchemy's recipe), so taking a trial is atomic, as it is on
    PostgreSQL with its row locks."""
    from sqlalchemy import event

    def no_implicit_begin(dbapi_connection, _record) -> None:
        dbapi_connection.isolation_level = None

    def begin_immediate(connection) -> None:
        connection.exec_driver_sql("BEGIN IMMEDIATE")

    event.listen(engine, "connect", no_implicit_begin)
    event.listen(engine, "begin", begin_immediate)
    engine.dispose()  # connections opened while the storage was set up get the listeners too


def redact(url: str) -> str:
    """``url`` with any password replaced by ***."""
    head, sep, tail = url.partition("://")
    if "@" in tail and ":" in tail.split("@", 1)[0]:
        user = tail.split("@", 1)[0].split(":", 1)[0]
        return f"{head}{sep}{user}:***@{tail.split('@', 1)[1]}"
    return url


# ------------------------------------------------------------------------------------------- tasks
@dataclass(frozen=True)
class TaskKind:
    """A registered task: the function, the trial's value of its result, the dashboard attributes of
    (item, result), and the Optuna parameters of an item (name -> (value, low, high))."""

    fn: Callable[[Any], Any]
    value: Callable[[Any], float]
    attrs: Callable[[Any, Any], dict] | None = None
    params: Callable[[Any], dict[str, tuple[float, float, float]]] | None = None


_KINDS: dict[str, TaskKind] = {}


def task_name(fn: Callable) -> str:
    return f"{fn.__module__}:{fn.__qualname__}"


def task(value: Callable[[Any], float], attrs: Callable[[Any, Any], dict] | None = None,
         params: Callable[[Any], dict[str, tuple[float, float, float]]] | None = None):
    """Decorator: register a module-level function of cpg_walker.experiments as a study task."""

    def register(fn: Callable) -> Callable:
        name = task_name(fn)
        if not name.startswith(TASK_MODULES) or "." in fn.__qualname__:
            raise TypeError(f"{name}: a task is a module-level function of {TASK_MODULES}*")
        _KINDS[name] = TaskKind(fn, value, attrs, params)
        return fn

    return register


def resolve(name: str) -> TaskKind:
    """The registered task ``module:function`` (its module imported, which registers it)."""
    module, _, _ = name.partition(":")
    if not module.startswith(TASK_MODULES):
        raise InputError(f"task {name!r} is not in {TASK_MODULES}*")
    importlib.import_module(module)
    if name not in _KINDS:
        raise InputError(f"{name!r} is not a registered task")
    return _KINDS[name]


def encode(x: Any) -> Any:
    """``x`` as JSON data: dataclasses (of cpg_walker) and tuples tagged so ``decode`` rebuilds them."""
    import numpy as np

    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {"__dataclass__": f"{type(x).__module__}:{type(x).__qualname__}",
                **{f.name: encode(getattr(x, f.name)) for f in dataclasses.fields(x)}}
    if isinstance(x, tuple):
        return {"__tuple__": [encode(v) for v in x]}
    if isinstance(x, (list, np.ndarray)):
        return [encode(v) for v in x]
    if isinstance(x, dict):
        bad = [k for k in x if not isinstance(k, str)]
        if bad or "__dataclass__" in x or "__tuple__" in x:
            raise TypeError(f"cannot store a mapping with the key(s) {bad or list(x)[:3]} in a study")
        return {k: encode(v) for k, v in x.items()}
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x)
    if x is None or isinstance(x, str):
        return x
    raise TypeError(f"cannot store a {type(x).__name__} in a study")


def decode(x: Any) -> Any:
    """The inverse of ``encode``."""
    if isinstance(x, list):
        return [decode(v) for v in x]
    if isinstance(x, dict):
        if "__tuple__" in x:
            return tuple(decode(v) for v in x["__tuple__"])
        if "__dataclass__" in x:
            module, _, qual = x["__dataclass__"].partition(":")
            if not module.startswith(DATA_MODULES):
                raise InputError(f"a study names the class {x['__dataclass__']!r}, not one of cpg_walker")
            cls = getattr(importlib.import_module(module), qual)
            if not dataclasses.is_dataclass(cls):
                raise InputError(f"{x['__dataclass__']} is not a dataclass")
            return cls(**{k: decode(v) for k, v in x.items() if k != "__dataclass__"})
        return {k: decode(v) for k, v in x.items()}
    return x


class TaskError(Exception):
    """A task raised: its trial fails with the message in the user attribute ``error`` (not retried)."""


# ------------------------------------------------------------------------------------------- workers
def _objective(worker: str, current: dict):
    def run(trial) -> float:
        import optuna

        attrs = trial.user_attrs
        current["number"] = trial.number
        if "fn" not in attrs:  # another worker took the last waiting trial between our look and our ask
            trial.set_user_attr("note", "no task: another worker took the last waiting one")
            raise optuna.TrialPruned("no task left")
        current.update(batch=attrs.get("batch"), index=attrs.get("index"), start=time.monotonic())
        kind = resolve(attrs["fn"])
        item = decode(attrs["item"])
        trial.set_user_attr("worker", worker)
        for name, (_, low, high) in (kind.params(item) if kind.params else {}).items():
            trial.suggest_float(name, low, high)  # the enqueued value
        try:
            _stop_point()
            _SIGNALLED["in_task"] = True
            try:
                result = kind.fn(item)
            finally:
                _SIGNALLED["in_task"] = False
            value = float(kind.value(result))
        except Exception as exc:
            trial.set_user_attr("error", f"{type(exc).__name__}: {exc}")
            raise TaskError(str(exc)) from exc
        trial.set_user_attr("result", encode(result))
        for key, v in (kind.attrs(item, result) if kind.attrs else {}).items():
            trial.set_user_attr(key, encode(v))
        if not math.isfinite(value):
            trial.set_user_attr("error", f"non-finite value {value}")
            raise TaskError(f"non-finite value {value}")
        return value

    return run


#: A worker process's stop request (SIGTERM, Ctrl-C) and whether it is inside a task's own code right now.
_SIGNALLED = {"stop": False, "in_task": False}


def _interrupt(*_: Any) -> None:
    """SIGTERM / SIGINT in a worker: interrupt the task at once when it is running its own code; anywhere
    else (the storage's transactions: an exception there left SQLite's write lock held by a transaction
    never ended, and the worker's next write waited the full timeout for it) only ask the worker to stop
    at its next safe point."""
    _SIGNALLED["stop"] = True
    if _SIGNALLED["in_task"]:
        _SIGNALLED["in_task"] = False
        raise KeyboardInterrupt


def _raise_interrupt(*_: Any) -> None:
    raise KeyboardInterrupt


def _install_stop_handlers(sigint: bool = True) -> None:
    signal.signal(signal.SIGTERM, _interrupt)
    if sigint:
        signal.signal(signal.SIGINT, _interrupt)


def _stop_point() -> None:
    """Raise KeyboardInterrupt here, at a safe point, when a stop was asked for."""
    if _SIGNALLED["stop"]:
        raise KeyboardInterrupt


def connect(url: str, name: str, wait_s: float = 0.0, poll_s: float = 0.5):
    """The study ``name`` in the storage at ``url`` (a SQLAlchemy URL), opened with the study's own engine
    settings (heartbeats, retries); waits up to ``wait_s`` for it to be created. InputError if absent."""
    import optuna

    plain = open_storage(url)
    end = time.monotonic() + wait_s
    while True:  # a study being created has no "engine" attribute for a moment
        try:
            engine = optuna.load_study(study_name=name, storage=plain).user_attrs.get("engine")
        except KeyError:
            engine = None
            if time.monotonic() >= end:
                raise InputError(f"no study {name!r} in {redact(url)}") from None
        if isinstance(engine, dict):
            break
        if time.monotonic() >= end:
            raise InputError(f"study {name!r} in {redact(url)} was not made by cpg-walker (no 'engine' "
                             "attribute)")
        time.sleep(poll_s)
    settings = EngineSettings(**engine)
    return optuna.load_study(study_name=name, storage=open_storage(url, settings)), settings


def work(url: str, name: str, worker: str | None = None, stop: Callable[[], bool] | None = None,
         until: Callable[[Any], bool] | None = None, log: Callable[[str], None] | None = None,
         wait_s: float = 0.0) -> int:
    """Run the study's waiting trials one at a time until ``stop()``, or ``until(study)``, or (neither
    given) the study is finished and nothing waits; ``log``: a line per trial run. Returns how many
    trials ran here."""
    import optuna
    from optuna.trial import TrialState

    study, settings = connect(url, name, wait_s)
    worker = worker or f"{socket.gethostname()}:{os.getpid()}"
    current: dict = {}
    objective = _objective(worker, current)
    ran = 0
    while not (stop and stop()):
        _stop_point()
        optuna.storages.fail_stale_trials(study)
        if until is not None and until(study):
            break
        if not study.get_trials(deepcopy=False, states=(TrialState.WAITING,)):
            if until is None and stop is None and study.user_attrs.get("finished"):
                break
            time.sleep(settings.poll_s)
            continue
        current.clear()
        try:
            study.optimize(objective, n_trials=1, catch=(TaskError,), gc_after_trial=False)
        except KeyboardInterrupt:
            _requeue(study, current.get("number"), settings)
            raise
        except (optuna.exceptions.UpdateFinishedTrialError, ValueError) as exc:
            told = "Cannot tell" in str(exc)
            elsewhere = told or isinstance(exc, optuna.exceptions.UpdateFinishedTrialError)
            if not elsewhere:
                raise
            # the trial was finished meanwhile by another worker (it was taken for stale and run again):
            # that worker's result stands
            if log is not None:
                log(f"{worker}: trial {current.get('number')} was finished elsewhere meanwhile; its result "
                    "dropped")
            continue
        ran += 1
        if log is not None and "start" in current:
            log(f"{worker}: trial {current['number']} ({current['batch']} #{current['index']}) done in "
                f"{time.monotonic() - current['start']:.1f} s")
    return ran


def _requeue(study, number: int | None, settings: EngineSettings) -> None:
    """Enqueue again the trial this worker was running when it was interrupted."""
    import optuna
    from optuna.trial import TrialState

    if number is None:
        return
    hit = [t for t in study.get_trials(deepcopy=False) if t.number == number and t.state == TrialState.FAIL]
    if hit and "fn" in hit[0].user_attrs:
        optuna.storages.RetryHeartbeatStaleTrialCallback(max_retry=settings.max_retry)(study, hit[0])


def _local_worker(url: str, name: str, worker: str, stop_event) -> None:
    """A coordinator's worker process (spawned): work until the coordinator sets ``stop_event``."""
    _install_stop_handlers(sigint=False)
    try:
        work(url, name, worker, stop=stop_event.is_set)
    except KeyboardInterrupt:
        pass


def run_workers(url: str, name: str, jobs: int, worker: str | None = None, wait_s: float = 0.0) -> int:
    """``cpg-walker worker``: ``jobs`` processes working on the study until it is finished and nothing waits
    (or Ctrl-C / SIGTERM: each running trial is enqueued again). Returns how many trials ran."""
    import multiprocessing as mp

    worker = worker or f"{socket.gethostname()}:{os.getpid()}"
    connect(url, name, wait_s)  # fail early, with the reason, before starting processes
    if jobs == 1:
        _install_stop_handlers()
        return work(url, name, worker, log=_stderr)
    ctx = mp.get_context("spawn")
    counts = ctx.Queue()
    procs = [ctx.Process(target=_counted_worker, args=(url, name, f"{worker}/{k}", counts), daemon=False)
             for k in range(jobs)]
    for p in procs:
        p.start()
    signal.signal(signal.SIGTERM, _raise_interrupt)  # this parent only waits: it forwards the stop
    try:
        for p in procs:
            p.join()
    except KeyboardInterrupt:
        for p in procs:
            if p.is_alive():
                os.kill(p.pid, signal.SIGTERM)
        for p in procs:
            p.join(timeout=30)
    ran = 0
    while not counts.empty():
        ran += counts.get()
    return ran


def _counted_worker(url: str, name: str, worker: str, counts) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent forwards Ctrl-C as SIGTERM
    _install_stop_handlers(sigint=False)
    n = 0
    try:
        n = work(url, name, worker, log=_stderr)
    except KeyboardInterrupt:
        pass
    counts.put(n)


def _stderr(line: str) -> None:
    import sys

    print(line, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------------- coordinator
def _batch(study, batch: str) -> dict[int, list]:
    out: dict[int, list] = {}
    for t in study.get_trials(deepcopy=False):
        if t.user_attrs.get("batch") == batch:
            out.setdefault(int(t.user_attrs["index"]), []).append(t)
    return out


def outcome(trials: list, max_retry: int) -> tuple[str, Any]:
    """("done", result) | ("error", message) | ("pending", None) | ("lost", the trial) of one task's trials
    (its retries). "lost": its last trial's worker was lost and the retry allowed is not enqueued (yet:
    whoever failed the trial enqueues it a moment later)."""
    from optuna.trial import TrialState

    done = sorted((t for t in trials if t.state == TrialState.COMPLETE), key=lambda t: t.number)
    if done:
        return "done", decode(done[0].user_attrs["result"])
    if any(t.state in (TrialState.WAITING, TrialState.RUNNING) for t in trials):
        return "pending", None
    failed = [t for t in trials if t.state == TrialState.FAIL]
    errors = [t.user_attrs["error"] for t in failed if "error" in t.user_attrs]
    if errors:
        return "error", errors[-1]
    if failed and len(failed) <= max_retry:
        return "lost", max(failed, key=lambda t: t.number)
    return "error", f"its worker was lost {len(failed)} time(s); not retried again"


class Engine:
    """One experiment's study and its local workers (context manager).

    ``Engine(url, name, experiment, jobs)``: opens (creates) the study; ``jobs`` local worker processes
    (1: the work runs in this process as ``map`` waits; 0: only workers elsewhere). ``map(fn, items,
    batch)`` enqueues the items not yet in the study's ``batch`` and returns every result in order, once
    all are done (by any worker). A finished experiment marks the study finished, which lets
    ``cpg-walker worker`` processes exit."""

    def __init__(self, url: str, name: str, experiment: str, jobs: int | None = None,
                 settings: EngineSettings | None = None, direction: str = "minimize",
                 attrs: dict | None = None, resume: bool = False, replace: bool = False):
        import optuna

        self.url, self.name, self.experiment = url, name, experiment
        self.jobs = (os.cpu_count() or 1) if jobs is None else int(jobs)
        if self.jobs < 0:
            raise InputError(f"--jobs must be >= 0, got {self.jobs}")
        storage = open_storage(url)
        if replace:  # the default storage of a run that does not resume: made afresh, as the files are
            try:
                optuna.delete_study(study_name=name, storage=storage)
            except KeyError:
                pass
        study = optuna.create_study(study_name=name, storage=storage, direction=direction,
                                    load_if_exists=True)
        kind = study.user_attrs.get("experiment")
        where = f"study {name!r} in {redact(url)}"
        if kind is not None and kind != experiment:
            raise InputError(f"{where} holds a {kind}, not a {experiment}; use another --study")
        n = len(study.get_trials(deepcopy=False))
        if n and not resume:
            raise InputError(f"{where} already holds a search of {n} trials; pass --resume to continue it, "
                             "or another --out / --study")
        for k, v in (attrs or {}).items():
            old, new = study.user_attrs.get(k), encode(v)
            if old is not None and old != new:
                diff = (sorted(x for x in {*old, *new} if old.get(x) != new.get(x))
                        if isinstance(old, dict) and isinstance(new, dict) else k)
                raise InputError(f"--resume: the saved {experiment} in {where} differs in {diff}; use "
                                 "another --out or --study")
        if kind is None:
            study.set_user_attr("experiment", experiment)
            study.set_user_attr("engine", dataclasses.asdict(settings or EngineSettings.load()))
            for k, v in (attrs or {}).items():
                study.set_user_attr(k, encode(v))
        study.set_user_attr("finished", False)
        self.study, self.settings = connect(url, name)
        self._procs: list = []
        self._stop = None

    @property
    def trials(self) -> list:
        return self.study.get_trials(deepcopy=False)

    def __enter__(self) -> Engine:
        if self.jobs > 1:
            import multiprocessing as mp

            ctx = mp.get_context("spawn")
            self._stop = ctx.Event()
            me = f"{socket.gethostname()}:{os.getpid()}"
            self._procs = [ctx.Process(target=_local_worker,
                                       args=(self.url, self.name, f"{me}/{k}", self._stop))
                           for k in range(self.jobs)]
            for p in self._procs:
                p.start()
        return self

    def __exit__(self, exc_type, *_: Any) -> None:
        if self._stop is not None:
            self._stop.set()
            for p in self._procs:
                p.join(timeout=60)
                if p.is_alive():
                    p.terminate()
                    p.join(timeout=10)
        if exc_type is None:
            self.study.set_user_attr("finished", True)

    def enqueue(self, fn: Callable, items: Iterable, batch: str) -> int:
        """Put the items not yet in ``batch`` into the study; how many were new. InputError when the batch
        already holds other tasks (another experiment under this name: use another --study)."""
        name = task_name(fn)
        kind = resolve(name)
        items = list(items)
        have = _batch(self.study, batch)
        extra = sorted(set(have) - set(range(len(items))))
        if extra:
            raise InputError(f"study {self.name!r} batch {batch!r} holds {len(have)} tasks, this run has "
                             f"{len(items)}: another experiment, use another --study")
        new = 0
        for k, item in enumerate(items):
            enc = encode(item)
            if k in have:
                if any(t.user_attrs.get("fn") != name or t.user_attrs.get("item") != enc for t in have[k]):
                    raise InputError(f"study {self.name!r} batch {batch!r} task {k} differs from this run's "
                                     "(another configuration): use another --study")
                continue
            params = kind.params(item) if kind.params else {}
            self.study.enqueue_trial({p: v[0] for p, v in params.items()},
                                     user_attrs={"batch": batch, "index": k, "fn": name, "item": enc})
            new += 1
        return new

    def status(self, batch: str, n: int) -> list[tuple[str, Any]]:
        """Each task's ``outcome``; a lost trial whose retry nobody enqueued within a grace period (its
        failer died in between) is enqueued again here."""
        import datetime

        import optuna

        have = _batch(self.study, batch)
        out = [outcome(have.get(k, []), self.settings.max_retry) for k in range(n)]
        now = datetime.datetime.now()
        for k, (state, trial) in enumerate(out):
            if state == "lost":
                if (now - trial.datetime_complete).total_seconds() > self.settings.grace_period_s:
                    optuna.storages.RetryHeartbeatStaleTrialCallback(
                        max_retry=self.settings.max_retry)(self.study, trial)
                out[k] = ("pending", None)
        return out

    def map(self, fn: Callable, items: Iterable, batch: str, progress=None) -> list:
        """Enqueue ``items`` as ``batch`` and return ``[fn(x) for x in items]`` (a task that raised: {"error":
        message}) once every one is done, by whichever worker."""
        import optuna

        items = list(items)
        self.enqueue(fn, items, batch)

        def done_count(study) -> int:
            return sum(s != "pending" for s, _ in self.status(batch, len(items)))

        def finished(study) -> bool:
            k = done_count(study)
            if progress is not None:
                progress.update(k)
            return k == len(items)

        if self.jobs == 1:  # in this process; numpy's global random state (a coordinator's, e.g. cma's) kept
            import numpy as np

            state = np.random.get_state()
            try:
                work(self.url, self.name, f"{socket.gethostname()}:{os.getpid()}", until=finished)
            finally:
                np.random.set_state(state)
        else:
            while not finished(self.study):
                if self._procs and not any(p.is_alive() for p in self._procs):
                    raise RuntimeError(f"every local worker of study {self.name!r} stopped; see their output")
                optuna.storages.fail_stale_trials(self.study)
                time.sleep(self.settings.poll_s)
        out = []
        for status, value in self.status(batch, len(items)):
            out.append(value if status == "done" else {"error": value})
        return out


def study_options(url: str | None, name: str | None, out_dir: str | Path,
                  default_name: str) -> tuple[str, str]:
    """(SQLAlchemy URL, study name) of an experiment's ``--storage``/``--study`` (the defaults: the SQLite
    file in ``out_dir``, the experiment's name)."""
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    return storage_url(url, out_dir), name or default_name
