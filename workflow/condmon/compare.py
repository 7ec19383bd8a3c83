"""Compare pipeline invocations logged in MLflow (console script ``condmon-compare``).

One row per parent run x classifier x protocol x measured percentage: mean accuracy and macro-F1
over repeats (held-out conditions of a repeat averaged first), the parent run's start time and
config hash; then the config keys whose values differ between the parents listed, with their
values (``differing_keys``). A config logged more than once (a rerun) counts once: the newest finished parent
per experiment and config hash, decided here at query time (``latest_parents``); unfinished
parents (a job killed, a server gone mid-way) never count. ``--all`` shows every invocation.

    condmon-compare --tracking-uri sqlite:///results/mlflow.db --experiment default --percent 0
"""

from __future__ import annotations

import argparse
import sys

import pandas as pd

from condmon.labels import protocol_title
from condmon.tracking import (
    DEFAULT_TRACKING_URI,
    TrackingError,
    check_tracking_server,
    existing_store,
)

KEYS = ["classifier", "protocol", "measured_percent"]


def parse_args(argv=None):
    parser = argparse.ArgumentParser(prog="condmon-compare", description=__doc__.split("\n")[0])
    parser.add_argument(
        "--tracking-uri",
        default=DEFAULT_TRACKING_URI,
        help=f"MLflow tracking URI (default {DEFAULT_TRACKING_URI}; relative "
        "sqlite paths are relative to the working directory)",
    )
    parser.add_argument(
        "--experiment",
        nargs="+",
        default=None,
        help="experiment (= pipeline run) names; default: all",
    )
    parser.add_argument(
        "--percent", type=int, nargs="+", default=None, help="only these measured percentages"
    )
    parser.add_argument(
        "--all",
        action="store_true",
        help="every invocation, also older ones of the same config and unfinished "
        "ones (columns status, latest)",
    )
    return parser.parse_args(argv)


def _column(frame: pd.DataFrame, name: str) -> pd.Series:
    """A search_runs column that may be absent when no run has that tag/param."""
    return (
        frame[name] if name in frame.columns else pd.Series(None, index=frame.index, dtype=object)
    )


def pipeline_parents(runs: pd.DataFrame) -> pd.DataFrame:
    """The parent runs of pipeline invocations in a ``mlflow.search_runs`` frame, each with a
    column ``latest``: it is the newest finished one of its experiment and config hash."""
    runs = runs.assign(**{"tags.config_hash": _column(runs, "tags.config_hash")})
    parent_of = _column(runs, "tags.mlflow.parentRunId")
    parents = runs[(parent_of.isna() | (parent_of == "")) & runs["tags.config_hash"].notna()].copy()
    finished = parents[parents["status"] == "FINISHED"].sort_values("start_time")
    newest = finished.drop_duplicates(["experiment_id", "tags.config_hash"], keep="last")["run_id"]
    parents["latest"] = parents["run_id"].isin(newest)
    return parents


def latest_parents(runs: pd.DataFrame) -> pd.DataFrame:
    """The newest finished parent per experiment and config hash (a rerun replaces, at query time)."""
    parents = pipeline_parents(runs)
    return parents[parents["latest"]].drop(columns="latest")


def comparison_table(
    runs: pd.DataFrame, experiment_names: dict, percents=None, every_invocation: bool = False
) -> pd.DataFrame:
    """Aggregate the ``mlflow.search_runs`` frame of parents and nested runs into the table."""
    columns = [
        "experiment",
        "parent_run_id",
        "started_utc",
        "config_hash",
        *(["status", "latest"] if every_invocation else []),
        *KEYS,
        "n_repeats",
        "accuracy_mean",
        "macro_f1_mean",
    ]
    if runs.empty:
        return pd.DataFrame(columns=columns)
    parents = pipeline_parents(runs)
    if not every_invocation:
        parents = parents[parents["latest"]]
    parents = pd.DataFrame(
        {
            "parent_run_id": parents["run_id"],
            "experiment": parents["experiment_id"].map(experiment_names),
            "started_utc": parents["start_time"].dt.strftime("%Y-%m-%d %H:%M:%S"),
            "config_hash": parents["tags.config_hash"],
            "status": parents["status"],
            "latest": parents["latest"].map({True: "yes", False: "no"}),
        }
    )
    children = runs[_column(runs, "tags.mlflow.parentRunId").isin(parents["parent_run_id"])]
    if children.empty:
        return pd.DataFrame(columns=columns)
    nested = pd.DataFrame(
        {
            "parent_run_id": children["tags.mlflow.parentRunId"],
            "classifier": children["params.classifier"],
            "protocol": children["params.protocol"].map(protocol_title),  # leaky ones say so
            "measured_percent": children["params.measured_percent"].astype(int),
            "repeat": children["params.repeat"].astype(int),
            "accuracy": children["metrics.accuracy"],
            "macro_f1": children["metrics.macro_f1"],
        }
    )
    if percents:
        nested = nested[nested["measured_percent"].isin(percents)]
    per_repeat = nested.groupby(["parent_run_id", *KEYS, "repeat"], as_index=False)[
        ["accuracy", "macro_f1"]
    ].mean()
    table = per_repeat.groupby(["parent_run_id", *KEYS], as_index=False).agg(
        n_repeats=("repeat", "nunique"),
        accuracy_mean=("accuracy", "mean"),
        macro_f1_mean=("macro_f1", "mean"),
    )
    table = parents.merge(table, on="parent_run_id")
    return table[columns].sort_values(["experiment", "started_utc", *KEYS]).reset_index(drop=True)


def differing_keys(runs: pd.DataFrame, parent_ids) -> pd.DataFrame:
    """The config keys (the parents' ``params.*``) whose values differ between the given parents:
    one row per parent (parent_run_id, config_hash), one column per key; a key a parent lacks
    counts as differing (shown empty)."""
    parents = runs[runs["run_id"].isin(list(parent_ids))].set_index("run_id")
    params = parents[[c for c in parents.columns if c.startswith("params.")]]
    differing = [c for c in params.columns if params[c].nunique(dropna=False) > 1]
    table = params[differing].rename(columns=lambda c: c[len("params.") :])
    table.insert(0, "config_hash", parents["tags.config_hash"])
    return table.rename_axis("parent_run_id").reset_index()


def main(argv=None) -> int:
    args = parse_args(argv)
    import mlflow

    try:
        uri = existing_store(args.tracking_uri)  # reading: never an empty store made here
        check_tracking_server(uri)
    except TrackingError as exc:
        print(f"condmon-compare: {exc}", file=sys.stderr)
        return 2
    client = mlflow.MlflowClient(uri)
    mlflow.set_tracking_uri(uri)
    if args.experiment:
        experiments = []
        for name in args.experiment:
            experiment = client.get_experiment_by_name(name)
            if experiment is None:
                print(f"condmon-compare: no experiment {name!r} at {uri}", file=sys.stderr)
                return 2
            experiments.append(experiment)
    else:
        experiments = client.search_experiments()
    names = {e.experiment_id: e.name for e in experiments}
    runs = mlflow.search_runs(experiment_ids=list(names)) if names else pd.DataFrame()
    table = comparison_table(runs, names, args.percent, args.all)
    if table.empty:
        print(f"no pipeline runs found at {uri}")
        return 0
    with pd.option_context("display.width", 200, "display.float_format", "{:.3f}".format):
        print(table.to_string(index=False))
        parents = table["parent_run_id"].unique()
        if len(parents) > 1:
            keys = differing_keys(runs, parents)
            names = list(keys.columns[2:])
            print(
                f"\nconfig keys that differ between these {len(parents)} runs: "
                + (", ".join(names) if names else "none (reruns of one config)")
            )
            if names:
                print(keys.fillna("").to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
