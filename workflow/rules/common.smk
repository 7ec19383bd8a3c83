# Helpers shared by the rules: output paths and the lists of jobs the config asks for.
import json
from pathlib import Path

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


SYSTEM = config["system"]  # gear: drivetrain model; bearing: ball-bearing rig on CWRU records
SPEEDS = [speed_label(s) for s in config["rig"]["speeds_rpm"]]
if SYSTEM == "bearing":
    from condmon.cwru import task_labels

    # The classes of the CWRU task; segments as long as the measured ones (cwru.segment_length).
    HEALTH_STATES = task_labels(config["cwru"]["task"])
    OUTPUT_RATE = config["cwru"]["fs_hz"]
    SEGMENT_SECONDS = config["cwru"]["segment_length"] / OUTPUT_RATE
    MODEL = config["bearing"]
else:
    HEALTH_STATES = config["rig"]["health_states"]
    OUTPUT_RATE = config["rig"]["output_rate_hz"]
    SEGMENT_SECONDS = config["rig"]["segment_seconds"]
    MODEL = config["model"]
# Numerical settings of every model run, with the rig's output rate.
if SYSTEM == "bearing":
    NUMERICS = dict(config["bearing"]["numerics"], output_rate_hz=OUTPUT_RATE)
else:
    NUMERICS = dict(config["numerics"], output_rate=OUTPUT_RATE)
# What an operating condition is (condition_holdout, strata): a load on the CWRU rig, whose
# records at one load differ by a few rpm; the speed on the gear bench.
CONDITION = config["hybrid"]["condition"] or ("load" if SYSTEM == "bearing" else "speed_rpm")
CLASSIFIERS = [name for name, c in config["classifiers"].items() if c["enabled"]]
PROTOCOLS = config["hybrid"]["protocols"]
N_BATCHES = -(-config["simulation"]["samples_per_state"] // config["simulation"]["samples_per_job"])
# Mesh stiffness models: the simulation's (model.mesh_stiffness_model) first, then the others
# calibration.mesh_stiffness_models lists; one calibration job each, all in the report.
# The bearing rig has one calibration ("rig").
SIM_STIFFNESS = config["model"]["mesh_stiffness_model"] if SYSTEM == "gear" else "rig"
STIFFNESS_MODELS = [SIM_STIFFNESS] + [m for m in config["calibration"]["mesh_stiffness_models"]
                                      if m != SIM_STIFFNESS and SYSTEM == "gear"]


wildcard_constraints:
    health="|".join(HEALTH_STATES),
    speed="[0-9.]+",
    batch="[0-9]+",
    classifier="|".join(CLASSIFIERS),
    protocol="|".join(PROTOCOLS),
    stiffness="simple|potential_energy|rig",


def batch_samples(batch):
    """Samples in one simulation job: full batches, then the remainder."""
    sim = config["simulation"]
    return min(sim["samples_per_job"], sim["samples_per_state"] - int(batch) * sim["samples_per_job"])


def simulated_batches(extension="parquet"):
    """Every simulation job's signal table (or its .json report)."""
    return expand(f"{RESULTS}/simulated/{{health}}/{{speed}}rpm/batch{{batch}}.{extension}",
                  health=HEALTH_STATES, speed=SPEEDS, batch=[f"{b:03d}" for b in range(N_BATCHES)])


def calibration_outputs(name, stiffness=None):
    """calibration/<mesh stiffness model>/<name>: of one model, or {model: path} of every one."""
    if stiffness is not None:
        return f"{RESULTS}/calibration/{stiffness}/{name}"
    return {m: f"{RESULTS}/calibration/{m}/{name}" for m in STIFFNESS_MODELS}


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
    """The CWRU .mat files of measured_dir, the user's measured table, or every virtual-bench
    part."""
    if SYSTEM == "bearing":
        folder = Path(config["measured_dir"])
        files = sorted(folder.glob("*.mat"))
        if not files:
            raise ValueError(f"measured_dir: no .mat files in {folder}")
        manifest = config["cwru"]["manifest"]
        if manifest == "auto":
            manifest = folder / "index.csv" if (folder / "index.csv").exists() else None
        return [str(f) for f in files] + ([str(manifest)] if manifest else [])
    if config["measured_table"] is not None:
        return [config["measured_table"]]
    return expand(f"{RESULTS}/measured/virtual_bench/{{health}}_{{speed}}rpm.parquet",
                  health=HEALTH_STATES, speed=SPEEDS)


def data_source():
    if SYSTEM == "bearing":
        return "measured"
    return "virtual_bench" if config["measured_table"] is None else "measured"


def statistical_feature_params():
    """features.statistical (envelope lines at the SKF 6205 defect orders of the CWRU drive end);
    None with spectrum features, so its settings never rerun a spectrum run's features."""
    if config["features"]["kind"] != "statistical":
        return None
    return dict(config["features"]["statistical"])


def final_outputs():
    return [
        *calibration_outputs("params.json").values(),
        f"{RESULTS}/report/accuracy.csv",
        f"{RESULTS}/report/summary.json",
        f"{RESULTS}/report/mlflow_run.json",
    ]


# Recorded with the MLflow runs so a comparison can group runs of the same config.
from condmon.signals import config_hash as _config_hash

config_hash = _config_hash(config)
