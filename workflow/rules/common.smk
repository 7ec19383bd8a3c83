# Helpers shared by the rules: output paths and the lists of jobs the config asks for.
import json

def canonical(section):
    """A config section with its keys sorted at every level: Snakemake compares params as
    written, so reordering keys in a config file must not rerun jobs."""
    if isinstance(section, dict):
        return {key: canonical(section[key]) for key in sorted(section)}
    if isinstance(section, list):
        return [canonical(item) for item in section]
    return section


config = canonical(config)
RESULTS = f"results/{config['run_name']}"
LOGS = f"{RESULTS}/logs"


def speed_label(speed):
    return f"{float(speed):g}"


SPEEDS = [speed_label(s) for s in config["rig"]["speeds_rpm"]]
# Numerical settings of every model run, with the rig's output rate.
NUMERICS = dict(config["numerics"], output_rate=config["rig"]["output_rate_hz"])
HEALTH_STATES = config["rig"]["health_states"]
CLASSIFIERS = [name for name, c in config["classifiers"].items() if c["enabled"]]
PROTOCOLS = config["hybrid"]["protocols"]
N_BATCHES = -(-config["simulation"]["samples_per_state"] // config["simulation"]["samples_per_job"])


wildcard_constraints:
    health="|".join(HEALTH_STATES),
    speed="[0-9.]+",
    batch="[0-9]+",
    classifier="|".join(CLASSIFIERS),
    protocol="|".join(PROTOCOLS),


def batch_samples(batch):
    """Samples in one simulation job: full batches, then the remainder."""
    sim = config["simulation"]
    return min(sim["samples_per_job"], sim["samples_per_state"] - int(batch) * sim["samples_per_job"])


def simulated_batches(extension="parquet"):
    """Every simulation job's signal table (or its .json report)."""
    return expand(f"{RESULTS}/simulated/{{health}}/{{speed}}rpm/batch{{batch}}.{extension}",
                  health=HEALTH_STATES, speed=SPEEDS, batch=[f"{b:03d}" for b in range(N_BATCHES)])


def train_outputs(name):
    return expand(f"{RESULTS}/train/{{classifier}}/{{protocol}}/{name}",
                  classifier=CLASSIFIERS, protocol=PROTOCOLS)


# Keys of a classifier section that choose what it trains on, not how it is built: the CNN may
# train on fewer measured percentages and repeats than hybrid lists (its fits are costly).
SELECTION_KEYS = ("enabled", "measured_percent", "repeats")


def classifier_params(name):
    return {k: v for k, v in config["classifiers"][name].items() if k not in SELECTION_KEYS}


def classifier_selection(name):
    """measured_percent / repeats of classifiers.<name> (None = all of hybrid's), checked here
    so a bad subset fails before any job runs."""
    section = config["classifiers"][name]
    selection = {"measured_percent": section.get("measured_percent"),
                 "repeats": section.get("repeats")}
    percents = selection["measured_percent"]
    if percents is not None and not set(percents) <= set(config["hybrid"]["measured_percent"]):
        raise ValueError(f"classifiers.{name}.measured_percent: {sorted(set(percents))} must be "
                         f"among hybrid.measured_percent {config['hybrid']['measured_percent']}")
    if selection["repeats"] is not None and selection["repeats"] > config["hybrid"]["repeats"]:
        raise ValueError(f"classifiers.{name}.repeats: {selection['repeats']} is more than "
                         f"hybrid.repeats ({config['hybrid']['repeats']})")
    return {key: value for key, value in selection.items() if value is not None}


for _name in CLASSIFIERS:
    classifier_selection(_name)


def measured_inputs(wildcards):
    """The user's measured table, or every virtual-bench part."""
    if config["measured_table"] is not None:
        return [config["measured_table"]]
    return expand(f"{RESULTS}/measured/virtual_bench/{{health}}_{{speed}}rpm.parquet",
                  health=HEALTH_STATES, speed=SPEEDS)


def data_source():
    return "virtual_bench" if config["measured_table"] is None else "measured"


def final_outputs():
    return [
        f"{RESULTS}/calibration/params.json",
        f"{RESULTS}/report/accuracy.csv",
        f"{RESULTS}/report/summary.json",
        f"{RESULTS}/report/mlflow_run.json",
    ]


# Recorded with the MLflow runs so a comparison can group runs of the same config.
from condmon.signals import config_hash as _config_hash

config_hash = _config_hash(config)
