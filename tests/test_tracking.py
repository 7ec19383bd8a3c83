"""MLflow tracking against a temporary SQLite store: structure, values, reruns, compare."""
import json
import os
import time

import mlflow
import pandas as pd
import pytest

import fake_train_outputs as fake
from condmon import compare, tracking

# raised inside MLflow's input-example handling, not by this code
pytestmark = pytest.mark.filterwarnings("ignore:Operation with range is deprecated")


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    """Two invocations of the same config, then one of another config."""
    root = tmp_path_factory.mktemp("results") / "demo"
    paths = fake.build(root)
    uri = f"sqlite:///{root.parent / 'mlflow.db'}"

    def log(config_hash, models="all"):
        return tracking.log_pipeline_run(
            uri, "demo", config_hash, "virtual_bench", fake.CLASSIFIERS, paths["metrics"],
            paths["predictions"], paths["models"], paths["features_measured"],
            paths["features_simulated"], models=models, workdir=root)

    first = log("hash-a")
    second = log("hash-a", models="first_repeat")
    other = log("hash-b", models="none")
    return uri, paths, first, second, other


def runs_of(uri, parent_id):
    client = mlflow.MlflowClient(uri)
    parent = client.get_run(parent_id)
    children = client.search_runs([parent.info.experiment_id],
                                  f"tags.mlflow.parentRunId = '{parent_id}'", max_results=1000)
    return parent, children


def test_parent_and_nested_structure(logged):
    uri, paths, first, _, _ = logged
    # classifiers x percents x repeats x (record_split + two held-out speeds)
    n_expected = len(fake.CLASSIFIERS) * len(fake.PERCENTS) * len(fake.REPEATS) * 3
    assert first["n_nested_runs"] == n_expected == first["n_models_logged"]
    parent, children = runs_of(uri, first["parent_run_id"])
    assert len(children) == n_expected
    tags = parent.data.tags
    assert tags["config_hash"] == "hash-a" and tags["snakemake_run_name"] == "demo"
    assert tags["data_source"] == "virtual_bench" and tags["data_source_synthetic"] == "true"
    assert tags["git_commit"]  # a hash, or "unknown" outside a repository
    assert parent.info.status == "FINISHED"
    assert mlflow.MlflowClient(uri).get_experiment(first["experiment_id"]).name == "demo"


def test_nested_run_values_match_metrics_csv(logged):
    uri, paths, first, _, _ = logged
    _, children = runs_of(uri, first["parent_run_id"])
    run = next(r for r in children if r.data.params["classifier"] == "logreg"
               and r.data.params["protocol"] == "record_split"
               and r.data.params["measured_percent"] == "50" and r.data.params["repeat"] == "1")
    metrics = pd.read_csv(fake_metrics_path(logged, "logreg", "record_split"))
    rows = metrics[(metrics.measured_percent == 50) & (metrics.repeat == 1)]
    overall = rows[rows.speed_rpm.isna()].iloc[0]
    assert run.data.metrics["accuracy"] == pytest.approx(overall.accuracy)
    assert run.data.metrics["macro_f1"] == pytest.approx(overall.macro_f1)
    at_600 = rows[rows.speed_rpm == 600].iloc[0]
    assert run.data.metrics["accuracy_600rpm"] == pytest.approx(at_600.accuracy)
    assert run.data.params["classifier.C"] == "1.0"
    assert run.data.params["n_train_measured"] == str(overall.n_train_measured)
    assert run.data.tags["leaky"] == "false"  # "true" only on segment_share runs

    client = mlflow.MlflowClient(uri)
    artifacts = {a.path for a in client.list_artifacts(run.info.run_id)}
    assert {"confusion_matrix.csv", "confusion_matrix.png"} <= artifacts
    confusion = client.download_artifacts(run.info.run_id, "confusion_matrix.csv")
    table = pd.read_csv(confusion, index_col=0)
    assert list(table.columns) == fake.LABELS
    assert table.to_numpy().sum() == overall.n_test
    # the logged model loads and predicts from a features row
    models = mlflow.search_logged_models(experiment_ids=[first["experiment_id"]],
                                         filter_string=f"source_run_id = '{run.info.run_id}'",
                                         output_format="list")
    assert len(models) == 1
    loaded = mlflow.sklearn.load_model(models[0].model_uri)
    example = pd.read_parquet(paths["features_measured"]).iloc[:2][fake.FEATURES].to_numpy()
    assert len(loaded.predict(example)) == 2


def test_second_invocation_supersedes_the_first(logged):
    uri, _, first, second, other = logged
    first_parent, first_children = runs_of(uri, first["parent_run_id"])
    second_parent, second_children = runs_of(uri, second["parent_run_id"])
    assert first_parent.data.tags["superseded"] == "true"
    assert first_parent.data.tags["superseded_by"] == second["parent_run_id"]
    assert all(r.data.tags["superseded"] == "true" for r in first_children)
    assert second_parent.data.tags["superseded"] == "false"
    assert set(second["superseded_run_ids"]) == {first["parent_run_id"]} | {
        r.info.run_id for r in first_children}
    # a different config hash supersedes nothing
    assert other["superseded_run_ids"] == []
    assert second_parent.data.tags["models_logged"] == "first_repeat"
    assert second["n_models_logged"] == second["n_nested_runs"] // len(fake.REPEATS)


def test_compare_prints_one_row_per_current_parent_and_setting(logged, capsys):
    uri, _, first, second, other = logged
    assert compare.main(["--tracking-uri", uri, "--experiment", "demo", "--percent", "0"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    header, rows = lines[0].split(), lines[1:]
    assert header[:4] == ["experiment", "parent_run_id", "started_utc", "config_hash"]
    # current parents (second, other) x classifiers x protocols at 0 %
    assert len(rows) == 2 * len(fake.CLASSIFIERS) * len(fake.PROTOCOL_HOLDOUTS)
    assert not any(first["parent_run_id"] in row for row in rows)
    assert sum(second["parent_run_id"] in row for row in rows) == 4

    # the numbers are the mean over repeats (holdouts averaged first) of the metrics
    runs = mlflow.search_runs(experiment_names=["demo"])
    table = compare.comparison_table(runs, {first["experiment_id"]: "demo"}, [0])
    metrics = pd.read_csv(fake_metrics_path(logged, "knn", "condition_holdout"))
    overall = metrics[(metrics.measured_percent == 0) & metrics.speed_rpm.isna()]
    expected = overall.groupby("repeat")["accuracy"].mean().mean()
    row = table[(table.parent_run_id == second["parent_run_id"]) & (table.classifier == "knn")
                & (table.protocol == "condition_holdout")].iloc[0]
    assert row.accuracy_mean == pytest.approx(expected) and row.n_repeats == 2

    assert compare.main(["--tracking-uri", uri, "--include-superseded"]) == 0
    rows = capsys.readouterr().out.strip().splitlines()[1:]
    assert len(rows) == 3 * len(fake.CLASSIFIERS) * len(fake.PROTOCOL_HOLDOUTS) * 2
    assert sum(first["parent_run_id"] in row and " true " in row for row in rows) == 8


def fake_metrics_path(logged, classifier, protocol):
    _, paths, *_ = logged
    return next(p for p in paths["metrics"] if f"{classifier}/{protocol}" in str(p))


def test_run_info_file(logged, tmp_path):
    _, _, first, _, _ = logged
    tracking.write_run_info(first, tmp_path / "mlflow_run.json")
    info = json.loads((tmp_path / "mlflow_run.json").read_text())
    assert {"parent_run_id", "experiment_id", "tracking_uri", "n_nested_runs"} <= set(info)


def test_unreachable_server_fails_fast_naming_the_uri(tmp_path):
    uri = "http://127.0.0.1:9"
    started = time.perf_counter()
    with pytest.raises(tracking.TrackingError, match="http://127.0.0.1:9.*unreachable"):
        tracking.log_pipeline_run(uri, "demo", "h", "virtual_bench", {}, [], [], [],
                                  tmp_path / "none.parquet")
    assert time.perf_counter() - started < 10
    assert compare.main(["--tracking-uri", uri]) == 2


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
        threading.Thread(target=server.serve_forever, kwargs=dict(poll_interval=0.05), daemon=True).start()
        servers.append(server)
        return f"http://127.0.0.1:{server.server_address[1]}"
    yield start
    for server in servers:
        server.shutdown()
        server.server_close()


@pytest.mark.parametrize("status, reachable", [(200, True), (401, True), (502, False), (503, False)])
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


TRACK_RUNNER = """
import json, sys, types
class Section(dict):
    __getattr__ = dict.__getitem__
args = json.loads(sys.argv[1])
snakemake = types.SimpleNamespace(params=Section(args["params"]), input=Section(args["input"]),
                                  output=Section(args["output"]), log=[args["log"]], rule="track")
exec(compile(open(args["script"]).read(), args["script"], "exec"),
     {"snakemake": snakemake, "__name__": "__main__"})
"""


def test_track_script_fails_in_seconds_naming_a_dead_server(tmp_path):
    """workflow/scripts/track.py as the `track` rule runs it (a fresh Python, `snakemake`
    injected), against a tracking URI on a closed port."""
    import subprocess
    import sys
    from conftest import ROOT
    uri = f"http://127.0.0.1:{closed_port()}"
    paths = fake.build(tmp_path / "demo")
    args = dict(script=str(ROOT / "workflow" / "scripts" / "track.py"), log=str(tmp_path / "track.log"),
                params=dict(tracking_uri=uri, run_name="demo", config_hash="h", data_source="virtual_bench",
                            classifier_params=fake.CLASSIFIERS),
                input=dict(metrics=list(map(str, paths["metrics"])),
                           predictions=list(map(str, paths["predictions"])),
                           models=list(map(str, paths["models"])),
                           features_measured=str(paths["features_measured"]),
                           features_simulated=str(paths["features_simulated"])),
                output=dict(run_info=str(tmp_path / "mlflow_run.json")))
    env = {k: v for k, v in os.environ.items() if not k.startswith("MLFLOW_HTTP_REQUEST")}
    started = time.perf_counter()
    result = subprocess.run([sys.executable, "-c", TRACK_RUNNER, json.dumps(args)], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=120)
    elapsed = time.perf_counter() - started
    log = (tmp_path / "track.log").read_text()
    assert result.returncode == 1, result.stderr[-2000:]
    assert f"MLflow tracking server {uri} is unreachable" in log, log
    assert "Traceback" not in log  # a plain message, not a stack
    assert not (tmp_path / "mlflow_run.json").exists()
    assert elapsed < 30, elapsed  # imports included; MLflow's own retries would take minutes
