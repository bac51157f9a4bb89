"""The many-walk experiments' engine (experiments/study.py): tasks stored as JSON and read back exactly,
storages and settings refused with the reason, a study kept or resumed but never mixed with another
experiment's; a worker interrupted (SIGTERM) hands its trial back at once; and the must-show on this
machine: a sweep through PostgreSQL run by two `cpg-walker worker`s in two network namespaces, one killed
mid-trial, its trial retried by the other, the tables identical to a one-machine run's (root, ``ip
netns`` and PostgreSQL needed for that one, else skipped)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from test_sweep import TINY as SWEEP_TINY

from cpg_walker.errors import InputError
from cpg_walker.experiments import scaleout
from cpg_walker.experiments.config_file import ConfigError
from cpg_walker.experiments.study import (
    Engine,
    EngineSettings,
    decode,
    encode,
    open_storage,
    redact,
    resolve,
    storage_url,
)
from cpg_walker.experiments.walk_runs import Push, WalkSpec

#: The sweep of the engine tests: test_sweep's tiny grid with our feedback only and one phase per
#: transition (11 trials), each walk 4 sim s after its command (a trial lasts long enough to be caught
#: running).
SWEEP = (SWEEP_TINY.replace("duration_after_s: 1.0", "duration_after_s: 4.0")
         .replace("variants: ['off', ours]", "variants: [ours]").replace("phases: 2,", "phases: 1,"))
#: Heartbeats of the tests' studies: a lost trial is enqueued again 4 s after its last heartbeat.
FAST = EngineSettings(heartbeat_interval_s=1.0, grace_period_s=4.0, max_retry=3, poll_s=0.2)


def test_items_and_results_are_stored_as_json_and_read_back_exactly():
    spec = WalkSpec(zeta=-1.25, alpha=0.5, start="at_10s", push=Push(12.0, 0.8, 0.1, -1.0),
                    schedule=((20.0, 1.0, 1.0),), overrides={"heading_gain": 0.25}, pathways=("amplitude",))
    item = ("walk", spec)
    back = decode(encode(item))
    assert back == item and isinstance(back[1], WalkSpec) and isinstance(back[1].push, Push)
    numpy = {"x": np.float64(0.1), "n": np.int64(3), "ok": np.bool_(True), "q": np.arange(3)}
    assert decode(encode(numpy)) == {"x": 0.1, "n": 3, "ok": True, "q": [0, 1, 2]}
    import json

    assert json.loads(json.dumps(encode(item))) == encode(item)  # plain JSON, as the storage keeps it
    with pytest.raises(TypeError, match="cannot store a set"):
        encode({1, 2})
    with pytest.raises(InputError, match="not one of cpg_walker"):
        decode({"__dataclass__": "subprocess:CompletedProcess", "args": "x", "returncode": 0})


def test_only_registered_tasks_of_the_experiments_run():
    assert resolve("cpg_walker.experiments.sweep:sweep_task").fn.__name__ == "sweep_task"
    with pytest.raises(InputError, match=r"not in cpg_walker\.experiments"):
        resolve("os:system")
    with pytest.raises(InputError, match="not a registered task"):
        resolve("cpg_walker.experiments.sweep:fall_thresholds")


def test_storage_urls_and_settings(tmp_path):
    assert storage_url("postgresql://u@h:5432/db") == "postgresql+psycopg://u@h:5432/db"
    assert storage_url("postgres://u@h/db") == "postgresql+psycopg://u@h/db"
    assert storage_url("postgresql+psycopg2://u@h/db") == "postgresql+psycopg2://u@h/db"
    assert storage_url(None, tmp_path) == f"sqlite:///{tmp_path.resolve()}/study.db"
    with pytest.raises(InputError, match="expected a database URL"):
        storage_url("results/study.db")
    assert redact("postgresql://me:secret@h/db") == "postgresql://me:***@h/db"
    refused = r"cannot open the study storage postgresql\+psycopg://me:\*\*\*@127\.0\.0\.1:1/db: .*refused"
    with pytest.raises(InputError, match=refused):
        open_storage(storage_url("postgresql://me:secret@127.0.0.1:1/db"))
    bad = tmp_path / "study.yaml"
    bad.write_text("heartbeat_interval_s: 5.0\ngrace_period_s: 8.0\n")
    with pytest.raises(ConfigError, match=r"study\.yaml:2 grace_period_s: must be more than twice"):
        EngineSettings.load(bad)
    bad.write_text("heartbeat_interval_s: 5.0\nretries: 3\n")
    with pytest.raises(ConfigError, match=r"study\.yaml:2 retries: unknown setting"):
        EngineSettings.load(bad)


def test_a_task_whose_worker_was_lost_waits_for_its_retry_until_the_retries_are_spent():
    import optuna
    from optuna.trial import TrialState

    from cpg_walker.experiments.study import outcome

    def trial(state, number, **attrs):
        value = {"value": 1.0} if state == TrialState.COMPLETE else {}
        t = optuna.create_trial(state=state, user_attrs=attrs, **value)
        t.number = number
        return t

    lost = trial(TrialState.FAIL, 3)
    assert outcome([lost], max_retry=2) == ("lost", lost)  # its failer enqueues the retry a moment later
    assert outcome([lost, trial(TrialState.WAITING, 4)], max_retry=2) == ("pending", None)
    assert outcome([lost, trial(TrialState.FAIL, 4), trial(TrialState.FAIL, 5)], max_retry=2)[0] == "error"
    raised = trial(TrialState.FAIL, 3, error="ValueError: x")
    assert outcome([raised], max_retry=2) == ("error", "ValueError: x")
    done = trial(TrialState.COMPLETE, 5, result={"__tuple__": [1, 2]})
    assert outcome([lost, done], max_retry=2) == ("done", (1, 2))


def test_a_study_is_resumed_only_when_asked_and_never_mixed(tmp_path):
    url = storage_url(None, tmp_path)
    with Engine(url, "s", "sweep", jobs=0, settings=FAST, attrs={"config": {"a": 1, "b": 2}}) as e:
        e.enqueue(resolve("cpg_walker.experiments.sweep:sweep_task").fn,
                  [("walk", WalkSpec(duration_after_s=0.5))], "sweep")
    with pytest.raises(InputError, match="already holds a search of 1 trials; pass --resume"):
        Engine(url, "s", "sweep", jobs=0)
    with pytest.raises(InputError, match=r"differs in \['b'\]"):
        Engine(url, "s", "sweep", jobs=0, attrs={"config": {"a": 1, "b": 3}}, resume=True)
    with pytest.raises(InputError, match="holds a sweep, not a transitions"):
        Engine(url, "s", "transitions", jobs=0, resume=True)
    e = Engine(url, "s", "sweep", jobs=0, attrs={"config": {"a": 1, "b": 2}}, resume=True)
    with pytest.raises(InputError, match="task 0 differs"):
        e.enqueue(resolve("cpg_walker.experiments.sweep:sweep_task").fn,
                  [("walk", WalkSpec(duration_after_s=0.6))], "sweep")
    Engine(url, "s", "sweep", jobs=0, replace=True)  # the default storage of a run that does not resume


def test_a_study_command_with_no_one_to_run_it_or_no_study_is_one_error_line(tmp_path, capsys):
    from cpg_walker.cli.main import main

    def error(argv: list[str]) -> str:
        assert main(argv) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and ": error: " in lines[0], lines
        return lines[0]

    assert "--jobs 0 needs --storage" in error(["sweep", "--out", str(tmp_path / "s"), "--jobs", "0"])
    db = f"sqlite:///{tmp_path}/x.db"
    assert "no study 'nope'" in error(["worker", "--storage", db, "--study", "nope"])
    assert "expected a database URL" in error(["worker", "--storage", "x.db", "--study", "s"])
    assert not (tmp_path / "s" / "sweep.json").exists()


def _worker(url: str, study: str, name: str, log: Path, prefix: list[str] | None = None) -> subprocess.Popen:
    cmd = [*(prefix or []), sys.executable, "-m", "cpg_walker.cli.main", "worker", "--storage", url,
           "--study", study, "--jobs", "1", "--name", name, "--wait", "120"]
    with log.open("w") as fh:
        return subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)


def _running(url: str, study: str, worker: str, deadline: float):
    """Wait until ``worker`` runs a trial; that trial."""
    import optuna
    from optuna.trial import TrialState

    storage = open_storage(url)
    while time.monotonic() < deadline:
        try:
            for t in optuna.load_study(study_name=study, storage=storage).get_trials(deepcopy=False):
                if t.state == TrialState.RUNNING and t.user_attrs.get("worker") == worker:
                    return t
        except KeyError:
            pass
        time.sleep(0.05)
    raise AssertionError(f"{worker} ran no trial in time")


def test_a_stopped_worker_hands_its_trial_back_at_once(tmp_path):
    """SIGTERM (as Ctrl-C): the trial fails and a copy waits at once, without the grace period; another
    worker then finishes the study."""
    from optuna.trial import TrialState

    from cpg_walker.experiments.random_commands import random_walk, spec

    url = storage_url(None, tmp_path)
    no_staleness = EngineSettings(heartbeat_interval_s=1.0, grace_period_s=600.0, poll_s=0.2)
    items = [spec(s, 12.0) for s in (1, 2)]
    done: dict = {}
    procs: list[subprocess.Popen] = []
    try:
        with Engine(url, "walks", "random-walks", jobs=0, settings=no_staleness) as engine:
            coord = threading.Thread(target=lambda: done.update(r=engine.map(random_walk, items, "walks")),
                                     daemon=True)
            coord.start()
            procs.append(_worker(url, "walks", "first", tmp_path / "first.log"))
            t = _running(url, "walks", "first", time.monotonic() + 120)
            os.killpg(procs[0].pid, signal.SIGTERM)
            assert procs[0].wait(timeout=60) == 130, (tmp_path / "first.log").read_text()
            trials = engine.trials
            assert next(x for x in trials if x.number == t.number).state == TrialState.FAIL
            again = [x for x in trials if t.number in x.system_attrs.get("retry_history", [])]
            assert [x.state for x in again] == [TrialState.WAITING]
            procs.append(_worker(url, "walks", "second", tmp_path / "second.log"))
            coord.join(timeout=180)
            assert not coord.is_alive()
        assert procs[1].wait(timeout=60) == 0, (tmp_path / "second.log").read_text()  # the study finished
        ran_by = {x.user_attrs["index"]: x.user_attrs["worker"] for x in engine.trials
                  if x.state == TrialState.COMPLETE}
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
    assert ran_by[t.user_attrs["index"]] == "second"
    assert [r["label"] for r in done["r"]] == ["seed 1", "seed 2"] and all("fell" in r for r in done["r"])


WHY_NO_HOSTS = scaleout.unavailable()
needs_hosts = pytest.mark.skipif(WHY_NO_HOSTS is not None,
                                 reason=f"needs namespaces and PostgreSQL: {WHY_NO_HOSTS}")


@pytest.mark.slow
@needs_hosts
def test_a_sweep_through_postgres_by_workers_in_two_namespaces_survives_a_killed_worker(tmp_path):
    from cpg_walker.experiments.sweep import run_sweep

    cfg = tmp_path / "sweep.yaml"
    cfg.write_text(SWEEP)
    run_sweep(tmp_path / "one_machine", jobs=1, config=str(cfg), progress_enabled=False)
    with scaleout.cluster(2) as (server, spokes):
        def coordinate(url: str) -> None:
            run_sweep(tmp_path / "hosts", jobs=0, config=str(cfg), progress_enabled=False, storage=url,
                      study="sweep", settings=FAST)

        run = scaleout.run_with_workers(spokes, server, "sweep", ["A", "B"], tmp_path / "logs", coordinate,
                                        kill="B")
    logs = {p.name: p.read_text()[-2000:] for p in (tmp_path / "logs").glob("*.log")}
    assert run["killed"] is not None, logs
    assert run["by_worker"].get("A", 0) >= 1 and run["by_worker"].get("B", 0) >= 1, (run, logs)
    lost = [f for f in run["failed"] if f["trial"] == run["killed"]["trial"]]
    assert lost and lost[0]["worker"] == "B", run
    assert [(a["state"], a["worker"]) for a in lost[0]["retried_as"]] == [("COMPLETE", "A")]
    assert run["worker_exit"]["A"] == 0, logs
    assert scaleout.compare_sweeps(tmp_path / "one_machine", tmp_path / "hosts") == {"sweep.json": True,
                                                                             "transitions.json": True}
