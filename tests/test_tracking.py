"""MLflow tracking against a temporary SQLite store: structure, values, models and their metrics,
datasets, parent summaries, two configs compared through mlflow.search_runs, reruns counted once
at query time, condmon-compare, a dead server."""

import json
import os
import re
import sqlite3
import subprocess
import time
from pathlib import Path

import mlflow
import pandas as pd
import pytest

import fake_train_outputs as fake
from condmon import compare, tracking

# two configs that differ in classifiers.svm.C only
CONFIG_A = {"run_name": "demo", "classifiers": {"svm": {"C": 1.0}, "knn": {"n_neighbors": 3}}}
CONFIG_B = {"run_name": "demo", "classifiers": {"svm": {"C": 0.02}, "knn": {"n_neighbors": 3}}}
N_RUNS = 2 * len(fake.PERCENTS) * len(fake.REPEATS) * 3  # record_split + two held-out speeds


def store_of(paths, config_hash) -> Path:
    """The model store of the outputs of fake.build under `config_hash` (as results/<run>/models/)."""
    return Path(paths["features_measured"]).parents[1] / "models" / config_hash


def log(paths, uri, config_hash, config, **options):
    """log_pipeline_run as the track job calls it, on the outputs of fake.build packaged into
    their run's model store of `config_hash` (once)."""
    run = tracking.TrackedRun(
        "demo", config_hash, "virtual_bench", config=config, healthy_state="healthy"
    )
    store = store_of(paths, config_hash)
    if not store.exists():
        fake.model_store(paths, store, config_hash)
    return tracking.log_pipeline_run(
        uri, run, fake.train_dirs(paths), fake.datasets(paths), store, **options
    )


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    """Config A logged twice (a rerun of the same config: the models of repeat 1 at 50 %, then
    those of repeat 0), then config B (no models)."""
    root = tmp_path_factory.mktemp("results")
    paths_a = fake.build(root / "a", classifiers=CONFIG_A["classifiers"])
    paths_b = fake.build(root / "b", classifiers=CONFIG_B["classifiers"])
    uri = f"sqlite:///{root / 'mlflow.db'}"
    first = log(
        paths_a, uri, "hash-a", CONFIG_A, log_models={"measured_percent": [50], "repeat": [1]}
    )
    second = log(paths_a, uri, "hash-a", CONFIG_A, log_models="first_repeat")
    other = log(paths_b, uri, "hash-b", CONFIG_B, log_models="none")
    return uri, paths_a, first, second, other


def nested_runs(uri, parent_id):
    client = mlflow.MlflowClient(uri)
    parent = client.get_run(parent_id)
    children = client.search_runs(
        [parent.info.experiment_id], f"tags.mlflow.parentRunId = '{parent_id}'", max_results=1000
    )
    return parent, children


def run_key(run):
    tags = run.data.tags
    return (
        f"{tags['classifier']}/{tags['protocol']}/p{tags['measured_percent']}/r{tags['repeat']}"
        + (f"/{tags['holdout']}" if tags["holdout"] else "")
    )


def metrics_of(paths, classifier, protocol):
    return pd.read_csv(next(p for p in paths["metrics"] if f"{classifier}/{protocol}" in str(p)))


@pytest.mark.slow
def test_parent_nested_runs_params_and_datasets(logged):
    uri, paths, first, _, _ = logged
    assert first["n_nested_runs"] == N_RUNS and first["n_models_logged"] == 6
    parent, children = nested_runs(uri, first["parent_run_id"])
    assert len(children) == N_RUNS and {r.info.status for r in children} == {"FINISHED"}
    assert len({run_key(r) for r in children}) == N_RUNS
    tags = parent.data.tags
    assert tags["config_hash"] == "hash-a" and tags["snakemake_run_name"] == "demo"
    assert tags["data_source"] == "virtual_bench" and tags["data_source_synthetic"] == "true"
    assert tags["git_commit"] and tags["n_nested_runs"] == str(N_RUNS)
    assert "superseded" not in tags  # older runs are never rewritten
    assert parent.info.status == "FINISHED"
    assert mlflow.MlflowClient(uri).get_experiment(first["experiment_id"]).name == "demo"
    assert parent.data.params["classifiers.svm.C"] == "1.0"  # the config, flattened
    # the signal and feature tables as inputs, digests of their files
    datasets = {d.dataset.name: d for d in parent.inputs.dataset_inputs}
    assert (
        set(datasets)
        == set(first["datasets"])
        == {"measured_signals", "simulated_signals", "measured_features", "simulated_features"}
    )
    assert {name: d.dataset.digest for name, d in datasets.items()} == first["datasets"]
    assert json.loads(datasets["simulated_signals"].dataset.profile)["files"] == len(fake.LABELS)
    assert json.loads(datasets["measured_features"].dataset.profile)["rows"] == len(
        pd.read_parquet(paths["features_measured"])
    )
    assert {d.tags[0].value for d in datasets.values()} == {"training", "training_and_test"}
    # a SQLite store on a local disk is switched to write-ahead logging
    with sqlite3.connect(uri[len("sqlite:///") :]) as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


@pytest.mark.slow
def test_nested_run_values_model_and_its_linked_metrics(logged):
    uri, paths, first, _, _ = logged
    _, children = nested_runs(uri, first["parent_run_id"])
    run = next(r for r in children if run_key(r) == "svm/record_split/p50/r1")
    rows = metrics_of(paths, "svm", "record_split")
    rows = rows[(rows.measured_percent == 50) & (rows.repeat == 1)]
    overall = rows[rows.speed_rpm.isna()].iloc[0]
    assert run.data.metrics["accuracy"] == pytest.approx(overall.accuracy)
    assert run.data.metrics["macro_f1"] == pytest.approx(overall.macro_f1)
    at_600 = rows[rows.speed_rpm == 600].iloc[0]
    assert run.data.metrics["accuracy_600rpm"] == pytest.approx(at_600.accuracy)
    assert run.data.params["classifier.C"] == "1.0"
    assert run.data.params["classifier.gamma"] == "scale"  # the registered default, as fitted
    assert run.data.params["n_train_measured"] == str(overall.n_train_measured)
    assert run.data.tags["leaky"] == "false"  # "true" only on segment_share runs
    # the model file the train job's info.json lists for this run
    info = json.loads(next(p for p in paths["info"] if "svm/record_split" in str(p)).read_text())
    listed = next(
        m["file"] for m in info["models"] if (m["measured_percent"], m["repeat"]) == (50, 1)
    )
    assert run.data.tags["model_file"].endswith(f"models/hash-a/svm/record_split/{listed}")

    # its confusion matrix, in the parent's table of them
    client = mlflow.MlflowClient(uri)
    confusion = pd.read_csv(
        client.download_artifacts(first["parent_run_id"], "confusion_matrices.csv")
    )
    assert list(confusion.columns) == [*tracking.KEYS, "true_label", *fake.LABELS]
    counts = confusion.query(
        "classifier == 'svm' and protocol == 'record_split' and measured_percent == 50 "
        "and repeat == 1"
    )
    assert (
        list(counts.true_label) == fake.LABELS
        and counts[fake.LABELS].to_numpy().sum() == overall.n_test
    )
    # its LoggedModel: loads and predicts; the run's metrics are linked to it, on the measured features
    mlflow.set_tracking_uri(uri)
    models = mlflow.search_logged_models(
        experiment_ids=[first["experiment_id"]],
        filter_string=f"source_run_id = '{run.info.run_id}'",
        output_format="list",
    )
    assert len(models) == 1
    linked = {m.key: m for m in models[0].metrics}
    assert linked["accuracy"].value == pytest.approx(overall.accuracy)
    assert linked["accuracy"].dataset_name == "measured_features"
    assert linked["accuracy"].dataset_digest == first["datasets"]["measured_features"]
    assert (
        models[0].params["classifier.C"] == "1.0" and models[0].tags["protocol"] == "record_split"
    )
    # the packaged model (a signal table in), its estimator the fitted one
    loaded = mlflow.pyfunc.load_model(models[0].model_uri).unwrap_python_model().model
    example = pd.read_parquet(paths["features_measured"]).iloc[:2][fake.FEATURES].to_numpy()
    assert len(loaded.estimator.predict(example)) == 2
    assert loaded.info["config_hash"] == "hash-a" and models[0].tags["model_digest"]
    signature = mlflow.models.get_model_info(models[0].model_uri).signature
    assert "signal" in signature.inputs.input_names()


@pytest.mark.slow
def test_the_config_chooses_which_models_are_logged(logged):
    """The runs the policy picks have their model logged, or linked to the one logged with the
    same digest (at 0 % measured every repeat and held-out speed fits the same model); no other
    run logs one."""
    uri, paths, first, second, other = logged
    assert other["n_models_logged"] == 0
    assert second["n_models_logged"] == N_RUNS // len(fake.REPEATS)  # first_repeat
    assert second["n_models_linked_not_logged"] > 0
    models = mlflow.search_logged_models(
        experiment_ids=[first["experiment_id"]], output_format="list"
    )
    store = store_of(paths, "hash-a")
    index = json.loads((store / "index.json").read_text())
    digest_of = {str((store / e["file"]).resolve()): e["digest"] for e in index["models"]}
    for info, expected in [
        (first, lambda r: r.data.tags["measured_percent"] == "50" and r.data.tags["repeat"] == "1"),
        (second, lambda r: r.data.tags["repeat"] == "0"),
    ]:
        _, children = nested_runs(uri, info["parent_run_id"])
        sources = {m.source_run_id for m in models}
        picked = [r for r in children if expected(r)]
        assert {r.info.run_id for r in children if r.info.run_id in sources} <= {
            r.info.run_id for r in picked
        }
        assert {digest_of[r.data.tags["model_file"]] for r in picked} <= {
            m.tags["model_digest"] for m in models
        }
        assert all(
            os.path.exists(r.data.tags["model_file"]) for r in children
        )  # every run names its file


@pytest.mark.slow
def test_parent_summary_metrics_are_the_means_over_repeats(logged):
    uri, paths, first, _, _ = logged
    parent, _ = nested_runs(uri, first["parent_run_id"])
    overall = metrics_of(paths, "knn", "condition_holdout").query("speed_rpm != speed_rpm")  # NaN
    for percent in fake.PERCENTS:
        at = overall[overall.measured_percent == percent]
        expected = at.groupby("repeat")["accuracy"].mean().mean()  # holdouts averaged first
        assert parent.data.metrics[
            f"accuracy.knn.condition_holdout.p{percent:03d}"
        ] == pytest.approx(expected)
    assert len([m for m in parent.data.metrics if m.startswith("accuracy.")]) == 2 * 2 * len(
        fake.PERCENTS
    )


@pytest.mark.slow
def test_two_configs_differing_in_svm_C_compared_through_search_runs(logged):
    """What the MLflow UI's compare view shows for two pipeline runs: the parameter that differs
    and the parents' summary metrics side by side."""
    uri, _, _, second, other = logged
    mlflow.set_tracking_uri(uri)
    runs = compare.latest_parents(mlflow.search_runs(experiment_names=["demo"]))
    runs = runs.set_index("tags.config_hash")
    assert set(runs.index) == {"hash-a", "hash-b"}
    assert set(runs["run_id"]) == {second["parent_run_id"], other["parent_run_id"]}
    assert runs.loc["hash-a", "params.classifiers.svm.C"] == "1.0"
    assert runs.loc["hash-b", "params.classifiers.svm.C"] == "0.02"
    assert (
        runs.loc["hash-a", "params.classifiers.knn.n_neighbors"]
        == runs.loc["hash-b", "params.classifiers.knn.n_neighbors"]
    )
    summary = [c for c in runs.columns if c.startswith("metrics.accuracy.svm.")]
    assert len(summary) == 2 * len(fake.PERCENTS) and runs[summary].notna().all().all()
    assert (runs.loc["hash-a", summary] != runs.loc["hash-b", summary]).any()


@pytest.mark.slow
def test_a_rerun_rewrites_nothing_and_counts_once(logged, capsys):
    uri, paths, first, second, other = logged
    first_parent, first_children = nested_runs(uri, first["parent_run_id"])
    assert first_parent.info.status == "FINISHED"
    assert all("superseded" not in r.data.tags for r in [first_parent, *first_children])
    # condmon-compare: the newest finished parent per config hash, one row per setting
    assert compare.main(["--tracking-uri", uri, "--experiment", "demo", "--percent", "0"]) == 0
    out, _, differing = capsys.readouterr().out.strip().partition("\n\n")
    lines = out.splitlines()
    # and the config key that differs between the two configs listed, with each one's value
    assert (
        differing.splitlines()[0]
        == "config keys that differ between these 2 runs: classifiers.svm.C"
    )
    keys = differing.splitlines()[1:]
    assert keys[0].split() == ["parent_run_id", "config_hash", "classifiers.svm.C"]
    assert sorted(line.split()[1:] for line in keys[1:]) == [["hash-a", "1.0"], ["hash-b", "0.02"]]
    header, rows = lines[0].split(), lines[1:]
    assert header[:4] == ["experiment", "parent_run_id", "started_utc", "config_hash"]
    assert len(rows) == 2 * 2 * len(fake.PROTOCOL_HOLDOUTS)  # 2 parents x classifiers x protocols
    assert not any(first["parent_run_id"] in row for row in rows)
    assert sum(second["parent_run_id"] in row for row in rows) == 4
    # the numbers: mean over repeats (held-out conditions averaged first)
    mlflow.set_tracking_uri(uri)
    table = compare.comparison_table(
        mlflow.search_runs(experiment_names=["demo"]), {first["experiment_id"]: "demo"}, [0]
    )
    overall = metrics_of(paths, "knn", "condition_holdout").query(
        "measured_percent == 0 and speed_rpm != speed_rpm"
    )
    row = table[
        (table.parent_run_id == second["parent_run_id"])
        & (table.classifier == "knn")
        & (table.protocol == "condition_holdout")
    ].iloc[0]
    assert row.accuracy_mean == pytest.approx(overall.groupby("repeat")["accuracy"].mean().mean())
    assert row.n_repeats == 2
    # --all: every invocation
    assert compare.main(["--tracking-uri", uri, "--all"]) == 0
    rows = capsys.readouterr().out.strip().partition("\n\n")[0].splitlines()[1:]
    assert len(rows) == 3 * 2 * len(fake.PROTOCOL_HOLDOUTS) * len(fake.PERCENTS)
    assert (
        sum(first["parent_run_id"] in row and " no " in row for row in rows) == 8
    )  # not the latest


@pytest.mark.slow
def test_an_unfinished_parent_never_counts(logged):
    """A parent left running (job killed, server gone mid-way) is ignored by the query, however new."""
    uri, _, _, second, _ = logged
    client = mlflow.MlflowClient(uri)
    unfinished = client.create_run(second["experiment_id"], tags={"config_hash": "hash-a"})
    try:
        mlflow.set_tracking_uri(uri)
        runs = compare.latest_parents(mlflow.search_runs(experiment_names=["demo"]))
        assert unfinished.info.run_id not in set(runs["run_id"])
        assert second["parent_run_id"] in set(runs["run_id"])
    finally:
        client.delete_run(unfinished.info.run_id)


def test_each_run_is_one_log_batch_and_mlflow_splits_large_ones(tmp_path, monkeypatch):
    """A nested run's params and metrics (a CNN run's mean training curves among them) go in one
    log_batch call; the parent's 250 config params in one log_params call, which MLflow splits
    into requests of its limit (100)."""
    history = pd.DataFrame(
        [
            {
                "member": m,
                "epoch": e,
                "train_loss": 1 / (e + 1),
                "val_loss": 1.0,
                "train_accuracy": 0.5,
                "val_accuracy": 0.5,
            }
            for m in range(3)
            for e in range(25 - 5 * m)
        ]
    )
    paths = fake.build(tmp_path / "demo")
    models = fake.train_dirs(paths)[0] / "models"  # knn/record_split
    history.assign(measured_percent=0, repeat=0, holdout="").to_parquet(
        models / tracking.HISTORY_FILE
    )
    calls, original = [], mlflow.MlflowClient.log_batch
    monkeypatch.setattr(
        mlflow.MlflowClient,
        "log_batch",
        lambda self, run_id, **kw: calls.append(run_id) or original(self, run_id, **kw),
    )
    config = {"section": {f"key{k:03d}": k for k in range(250)}}
    info = log(paths, f"sqlite:///{tmp_path / 'mlflow.db'}", "h", config, log_models="none")
    parent, children = nested_runs(info["tracking_uri"], info["parent_run_id"])
    assert sorted(calls.count(r.info.run_id) for r in children) == [1] * N_RUNS
    assert len(parent.data.params) == 250 and parent.data.params["section.key249"] == "249"
    run = next(r for r in children if run_key(r) == "knn/record_split/p0/r0")
    client = mlflow.MlflowClient(info["tracking_uri"])
    loss = client.get_metric_history(run.info.run_id, "train_loss")
    assert [m.step for m in loss] == list(range(25))
    assert loss[0].value == 1.0 and loss[-1].value == pytest.approx(
        1 / 25
    )  # the members still running
    assert run.data.metrics["epochs_run_mean"] == pytest.approx((24 + 19 + 14) / 3)
    members = pd.read_csv(client.download_artifacts(run.info.run_id, "training_history.csv"))
    pd.testing.assert_frame_equal(members, history[members.columns.tolist()])


def test_a_dataset_inserted_meanwhile_by_another_pipeline_is_logged_again(monkeypatch):
    """Pipelines logging the same table into one experiment at once race on the store's unique
    (experiment, name, digest) row: the loser logs its inputs again; other errors pass through."""
    from mlflow.exceptions import MlflowException

    race = MlflowException(
        "BAD_REQUEST: (sqlite3.IntegrityError) UNIQUE constraint failed: "
        "datasets.experiment_id, datasets.name, datasets.digest"
    )
    outcomes, calls = [race, None], []

    def log_inputs(datasets, **options):
        calls.append(len(datasets))
        if outcome := outcomes.pop(0):
            raise outcome

    monkeypatch.setattr(mlflow, "log_inputs", log_inputs)
    tracking.log_inputs({"measured_signals": object(), "simulated_signals": object()})
    assert calls == [2, 2]
    outcomes[:] = [MlflowException("BAD_REQUEST: no such experiment")]
    with pytest.raises(MlflowException, match="no such experiment"):
        tracking.log_inputs({"measured_signals": object()})
    outcomes[:] = [race] * 3
    with pytest.raises(MlflowException, match="UNIQUE"):  # a race that never settles still fails
        tracking.log_inputs({"measured_signals": object()})


@pytest.mark.slow
def test_run_info_file(logged, tmp_path):
    _, _, first, _, _ = logged
    tracking.write_run_info(first, tmp_path / "mlflow_run.json")
    info = json.loads((tmp_path / "mlflow_run.json").read_text())
    assert {"parent_run_id", "experiment_id", "tracking_uri", "n_nested_runs", "datasets"} <= set(
        info
    )


def test_unreachable_server_fails_fast_naming_the_uri(tmp_path):
    uri = "http://127.0.0.1:9"
    started = time.perf_counter()
    with pytest.raises(tracking.TrackingError, match="http://127.0.0.1:9.*unreachable"):
        tracking.log_pipeline_run(
            uri, tracking.TrackedRun("demo", "h", "virtual_bench"), [], {}, tmp_path
        )
    assert time.perf_counter() - started < 10
    assert compare.main(["--tracking-uri", uri]) == 2


def test_compare_on_a_missing_store_says_so_and_creates_none(tmp_path, capsys):
    assert compare.main(["--tracking-uri", f"sqlite:///{tmp_path}/results/mlflow.db"]) == 2
    assert f"no MLflow store at {tmp_path}/results/mlflow.db" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_relative_sqlite_uri_is_relative_to_the_working_directory(tmp_path):
    uri = tracking.resolve_tracking_uri("sqlite:///results/mlflow.db", workdir=tmp_path)
    assert uri == f"sqlite:///{tmp_path.resolve()}/results/mlflow.db"
    assert (tmp_path / "results").is_dir()


# --------------------------------------------------------------------------- server down
def closed_port() -> int:
    """A local port nothing listens on (bound, then released)."""
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.fixture
def http_server():
    """Start a local HTTP server answering every GET with the given status; yields its URI."""
    import http.server
    import threading

    servers = []

    def start(status):
        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):
                self.send_response(status)
                self.end_headers()
                self.wfile.write(b"OK")

            def log_message(self, *args):
                pass

        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        threading.Thread(
            target=server.serve_forever, kwargs=dict(poll_interval=0.05), daemon=True
        ).start()
        servers.append(server)
        return f"http://127.0.0.1:{server.server_address[1]}"

    yield start
    for server in servers:
        server.shutdown()
        server.server_close()


@pytest.mark.parametrize(
    "status, reachable", [(200, True), (401, True), (502, False), (503, False)]
)
def test_probe_accepts_any_answer_but_a_gateway_error(http_server, status, reachable):
    uri = http_server(status)
    if reachable:
        tracking.check_tracking_server(uri, timeout_s=2)
    else:
        with pytest.raises(tracking.TrackingError, match=rf"{uri} is unreachable \(HTTP {status}"):
            tracking.check_tracking_server(uri, timeout_s=2)


def test_a_server_that_accepts_but_never_answers_fails_after_the_probe_timeout():
    import socket

    with socket.socket() as sock:  # listens (the kernel completes connections) but never replies
        sock.bind(("127.0.0.1", 0))
        sock.listen(4)
        uri = f"http://127.0.0.1:{sock.getsockname()[1]}"
        started = time.perf_counter()
        with pytest.raises(tracking.TrackingError, match=rf"{uri} is unreachable \(.*timed out"):
            tracking.check_tracking_server(uri, timeout_s=1)
        assert time.perf_counter() - started < 5


@pytest.mark.slow
def test_track_script_fails_in_seconds_naming_a_dead_server(tmp_path):
    """workflow/scripts/track.py as the `track` rule runs it (a fresh Python, `snakemake`
    injected), against a tracking URI on a closed port."""
    uri = f"http://127.0.0.1:{closed_port()}"
    paths = fake.build(tmp_path / "demo")
    env = {k: v for k, v in os.environ.items() if not k.startswith("MLFLOW_HTTP_REQUEST")}
    command = fake.track_job(paths, uri, tmp_path)
    started = time.perf_counter()
    result = subprocess.run(
        command,
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    elapsed = time.perf_counter() - started
    log_text = (tmp_path / "track.log").read_text()
    assert result.returncode == 1, result.stderr[-2000:]
    assert f"MLflow tracking server {uri} is unreachable" in log_text, log_text
    assert "Traceback" not in log_text  # a plain message, not a stack
    assert not (tmp_path / "mlflow_run.json").exists() and not (tmp_path / "models").exists()
    assert elapsed < 30, elapsed  # imports included; MLflow's own retries would take minutes


def test_parent_runs_have_readable_names_with_the_changed_keys(logged):
    """A parent is named by its run and time, not its hash (kept as a tag); a parent of another
    config than the experiment's previous parent names the keys that changed."""
    uri, _, first, second, other = logged
    client = mlflow.MlflowClient(uri)
    names = {
        info["config_hash"] + str(i): client.get_run(info["parent_run_id"]).info.run_name
        for i, info in enumerate((first, second, other))
    }
    stamp = r"demo \d{4}-\d\d-\d\d \d\d:\d\d"
    assert re.fullmatch(stamp, names["hash-a0"])  # the experiment's first parent
    assert re.fullmatch(stamp, names["hash-a1"])  # a rerun of the same config
    assert re.fullmatch(stamp + r" \(classifiers\.svm\.C=0\.02\)", names["hash-b2"])
    assert all("hash" not in name for name in names.values())
    assert client.get_run(other["parent_run_id"]).data.tags["config_hash"] == "hash-b"
    # MLflow 3's UI opens the experiment as "Machine learning" (its runs), not on a GenAI overview
    experiment = client.get_experiment(first["experiment_id"])
    assert experiment.tags["mlflow.experimentKind"] == "custom_model_development"


def test_changed_keys_are_few_and_short():
    assert tracking.changed_keys({"a": "1", "b": "2"}, {"a": "1", "b": "3"}) == "b=2"
    assert tracking.changed_keys({"a": "x" * 30}, {}) == "a"  # a long value by its key alone
    assert tracking.changed_keys({k: "1" for k in "abcde"}, {}) == "a=1, b=1, c=1, +2 more"
    assert tracking.changed_keys({"a": "1"}, {"a": "1", "gone": "2"}) == "gone"
