"""A team's MLflow tracking server: `mlflow server` with a SQLite backend and an artifact root,
started on loopback (a free port) by the tests. Track jobs of several configs log to it at once
(workflow/scripts/track.py as the rule runs it, on small fake train outputs: the pipelines before
it add nothing here); the server dying mid-logging fails the job naming it, and a rerun after the
restart completes the logging."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import mlflow
import pytest

import fake_train_outputs as fake
from condmon import compare

pytestmark = pytest.mark.slow  # a live MLflow server and several track jobs: minutes
N_PIPELINES = 3
N_RUNS = (
    2 * len(fake.PERCENTS) * len(fake.REPEATS) * 3
)  # classifiers x ... x (record split + 2 held-out speeds)


# MLflow's job execution (a huey job runner and its consumers: the server's GenAI jobs, which no
# track job calls) off: it started nine more Pythons with every server start (about 8 CPU-s
# each time, on a 2-core CI machine) and polled beside the logging. Tracking is the same server.
SERVER_ENV = {**os.environ, "MLFLOW_SERVER_ENABLE_JOB_EXECUTION": "false"}


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class Server:
    """`mlflow server` on 127.0.0.1:<port>, its store and artifacts under ``root``."""

    def __init__(self, root, port):
        self.root, self.port = root, port
        self.uri = f"http://127.0.0.1:{port}"
        self.process = None

    def start(self, timeout=180):
        log = open(self.root / "server.log", "a")
        self.process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "mlflow",
                "server",
                "--host",
                "127.0.0.1",
                "--port",
                str(self.port),
                "--backend-store-uri",
                f"sqlite:///{self.root / 'server.db'}",
                "--artifacts-destination",
                str(self.root / "artifacts"),
                "--workers",
                "2",
            ],
            cwd=self.root,
            env=SERVER_ENV,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            assert self.process.poll() is None, (self.root / "server.log").read_text()[-3000:]
            try:
                urllib.request.urlopen(f"{self.uri}/health", timeout=2).close()
                return self
            except OSError:
                time.sleep(0.5)
        raise AssertionError(f"mlflow server did not answer in {timeout} s")

    def kill(self):
        if self.process and self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)  # the server and its workers, at once
            self.process.wait(timeout=30)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    root = tmp_path_factory.mktemp("mlflow_server")
    server = Server(root, free_port()).start()
    yield server
    server.kill()


def track(paths, server, workdir, config_hash, run_name="team", log_models="none"):
    """A track job (a fresh Python) logging to the server; returns its Popen."""
    workdir.mkdir(parents=True, exist_ok=True)
    config = {"run_name": run_name, "tracking": {"uri": server.uri}, "hash": config_hash}
    return subprocess.Popen(
        fake.track_job(paths, server.uri, workdir, config_hash, run_name, config, log_models),
        cwd=workdir,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def parents_and_children(uri, experiment):
    client = mlflow.MlflowClient(uri)
    experiment_id = client.get_experiment_by_name(experiment).experiment_id
    runs = client.search_runs([experiment_id], max_results=5000)
    parents = [r for r in runs if "mlflow.parentRunId" not in r.data.tags]
    children = {
        p.info.run_id: [r for r in runs if r.data.tags.get("mlflow.parentRunId") == p.info.run_id]
        for p in parents
    }
    return parents, children


def test_concurrent_track_jobs_of_several_configs_log_every_run_once(server, tmp_path):
    # different configs: the SVM's C and the KNN's k differ, so do every fitted model (none is
    # linked to another pipeline's) and the metrics
    jobs = []
    for i in range(N_PIPELINES):
        paths = fake.build(
            tmp_path / f"p{i}" / "results",
            classifiers={"svm": {"C": 0.5 * 2**i}, "knn": {"n_neighbors": 3 + i}},
        )
        # all into one experiment at once: its creation races too
        jobs.append(
            track(paths, server, tmp_path / f"p{i}", f"hash-{i}", log_models="first_repeat")
        )
    for job in jobs:
        output = job.communicate(timeout=600)[0]
        assert job.returncode == 0, output[-3000:]
    parents, children = parents_and_children(server.uri, "team")
    assert sorted(p.data.tags["config_hash"] for p in parents) == [
        f"hash-{i}" for i in range(N_PIPELINES)
    ]
    for parent in parents:
        assert parent.info.status == "FINISHED"
        nested = children[parent.info.run_id]
        assert len(nested) == N_RUNS and {r.info.status for r in nested} == {"FINISHED"}
        keys = {
            (
                r.data.tags["classifier"],
                r.data.tags["protocol"],
                r.data.tags["measured_percent"],
                r.data.tags["repeat"],
                r.data.tags["holdout"],
            )
            for r in nested
        }
        assert len(keys) == N_RUNS  # none twice, none lost
        assert len({d.dataset.name for d in parent.inputs.dataset_inputs}) == 4
    mlflow.set_tracking_uri(server.uri)
    experiment_id = mlflow.get_experiment_by_name("team").experiment_id
    models = mlflow.search_logged_models(experiment_ids=[experiment_id], output_format="list")
    # every pipeline's first-repeat models, each logged (or linked to its twin of the same digest:
    # at 0 % measured the repeats and held-out speeds fit the same model)
    picked = set()
    for i in range(N_PIPELINES):
        info = json.loads((tmp_path / f"p{i}" / "mlflow_run.json").read_text())
        assert info["n_models_logged"] == N_RUNS // len(fake.REPEATS)
        index = json.loads((tmp_path / f"p{i}" / "models" / "index.json").read_text())
        picked |= {e["digest"] for e in index["models"] if e["repeat"] == 0}
    assert picked <= {m.tags["model_digest"] for m in models}
    assert len(models) <= N_PIPELINES * N_RUNS // len(fake.REPEATS)
    # the models' artifacts went through the server to its artifact root
    assert mlflow.pyfunc.load_model(models[0].model_uri) is not None
    assert any((server.root / "artifacts").rglob("MLmodel"))


def test_the_server_dying_mid_logging_fails_the_job_naming_it_and_a_rerun_completes(
    server, tmp_path
):
    # a set large enough that its logging (every model) takes seconds: 24 runs, each a model
    percents = [0, 100]
    paths = fake.build(tmp_path / "results", percents=percents)
    n_runs = N_RUNS // len(fake.PERCENTS) * len(percents)
    client = mlflow.MlflowClient(server.uri)
    job = track(paths, server, tmp_path / "job", "hash-crash", run_name="crash", log_models="all")
    started = time.monotonic()
    while True:  # until a few nested runs are on the server
        assert job.poll() is None, "the job finished before the server could be killed"
        assert time.monotonic() - started < 300
        experiment = client.get_experiment_by_name("crash")
        if experiment and len(client.search_runs([experiment.experiment_id], max_results=10)) >= 4:
            break
        time.sleep(0.2)
    server.kill()
    killed = time.monotonic()
    output = job.communicate(timeout=300)[0]
    log = (tmp_path / "job" / "track.log").read_text()
    assert job.returncode == 1, output[-3000:]
    assert time.monotonic() - killed < 60
    assert f"MLflow tracking server {server.uri} failed while logging" in log, log[-3000:]
    assert "rerun the track job" in log and "Traceback" not in log
    assert not (tmp_path / "job" / "mlflow_run.json").exists()

    server.start()  # the same server, store and port: the rerun completes the logging
    rerun = track(paths, server, tmp_path / "job", "hash-crash", run_name="crash", log_models="all")
    output = rerun.communicate(timeout=600)[0]
    assert rerun.returncode == 0, output[-3000:]
    info = json.loads((tmp_path / "job" / "mlflow_run.json").read_text())
    parents, children = parents_and_children(server.uri, "crash")
    assert len(parents) == 2  # the unfinished one stays as it was, and is never counted
    assert {p.info.status for p in parents if p.info.run_id != info["parent_run_id"]} <= {
        "RUNNING",
        "FAILED",
    }
    assert len(children[info["parent_run_id"]]) == n_runs
    mlflow.set_tracking_uri(server.uri)
    latest = compare.latest_parents(mlflow.search_runs(experiment_names=["crash"]))
    assert list(latest["run_id"]) == [info["parent_run_id"]]
