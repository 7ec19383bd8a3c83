# Helpers shared by the rules: output paths and the lists of jobs the config asks for.
import json
import re
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
# wall time and peak memory of every job (Snakemake benchmark files), summarised in the report
BENCHMARKS = f"{RESULTS}/benchmarks"


# The simulated system (condmon.systems): its health states, speeds, measured inputs, calibrations
# and the config each job needs; no rule looks at the system's name.
from condmon.systems import get_system

SYSTEM = get_system(config)
HEALTH_STATES = SYSTEM.health_states
# the simulation's operating points (OperatingPoint.label): 450rpm, or 450rpm_20Nm with rig.loads
POINTS = [point.label for point in SYSTEM.operating_points]
# What an operating condition is (condition_holdout, strata); the config's, or the system's own.
CONDITION = config["hybrid"]["condition"]
CLASSIFIERS = [name for name, c in config["classifiers"].items() if c["enabled"]]
PROTOCOLS = config["hybrid"]["protocols"]
# the joined methods: a classifier inside its training range, the physics rule outside (joined.py)
JOINED = list(config["joined"]["classifiers"])
N_BATCHES = -(
    -config["simulation"]["samples_per_state"]
    // config["simulation"]["samples_per_job"]
)
# One calibration job per variant (System.calibration_variants), the simulation's first.
CALIBRATIONS = SYSTEM.calibration_variants()
SIM_CALIBRATION = CALIBRATIONS[0]
MEASURED_PARTS = SYSTEM.measured_parts()  # a synthetic bench's jobs, or none
HEALTHY_PARTS = SYSTEM.healthy_parts()  # those the calibrations read
# the calibrations read the bench's healthy parts alone and run while it makes the others
EARLY_CALIBRATION = (
    bool(set(MEASURED_PARTS) - set(HEALTHY_PARTS)) and not SYSTEM.measured_files()
)
# Per-state calibration (calibration.per_state): the fault states whose own model is tuned; their
# first record per condition joins the calibration set (the reserve every split keeps out).
STATE_CALIBRATIONS = config["calibration"]["per_state"]["states"]
RESERVE = dict(config["calibration"]["reserve"], fault_states=STATE_CALIBRATIONS)


wildcard_constraints:
    health="|".join(HEALTH_STATES),
    point="|".join(re.escape(label) for label in POINTS),
    batch="[0-9]+",
    classifier="|".join(CLASSIFIERS),
    protocol="|".join(PROTOCOLS),
    variant="|".join(CALIBRATIONS),
    state="|".join(STATE_CALIBRATIONS) or "(?!)",
    part="|".join(MEASURED_PARTS) or "(?!)",


def batch_samples(batch):
    """Samples in one simulation job: full batches, then the remainder."""
    sim = config["simulation"]
    return min(
        sim["samples_per_job"],
        sim["samples_per_state"] - int(batch) * sim["samples_per_job"],
    )


BATCHES = [f"{b:03d}" for b in range(N_BATCHES)]


def simulated_batches(extension="parquet"):
    """Every simulation job's signal table (or its .json report)."""
    return expand(
        f"{RESULTS}/simulated/{{health}}/{{point}}/batch{{batch}}.{extension}",
        health=HEALTH_STATES,
        point=POINTS,
        batch=BATCHES,
    )


def calibration_outputs(name, calibration=None):
    """calibration/<calibration>/<name>: of one calibration, or {calibration: path} of every one."""
    if calibration is not None:
        return f"{RESULTS}/calibration/{calibration}/{name}"
    return {m: f"{RESULTS}/calibration/{m}/{name}" for m in CALIBRATIONS}


def state_calibration_output(health):
    """{state_calibration: state_calibration/<health>/params.json} for a state with its own
    calibrated model (calibration.per_state), else nothing."""
    if health not in STATE_CALIBRATIONS:
        return {}
    return {"state_calibration": f"{RESULTS}/state_calibration/{health}/params.json"}


def calibration_background_outputs(calibration, plot=True):
    """{background: calibration/<calibration>/background.parquet (and background_plot: its PNG)}
    with calibration.background on, else nothing."""
    if not config["calibration"]["background"]:
        return {}
    outputs = {"background": f"{RESULTS}/calibration/{calibration}/background.parquet"}
    if plot:
        outputs["background_plot"] = (
            f"{RESULTS}/calibration/{calibration}/background.png"
        )
    return outputs


def train_outputs(name):
    return expand(
        f"{RESULTS}/train/{{classifier}}/{{protocol}}/{name}",
        classifier=CLASSIFIERS,
        protocol=PROTOCOLS,
    )


def joined_outputs(name):
    return expand(
        f"{RESULTS}/joined/joined_{{classifier}}/{{protocol}}/{name}",
        classifier=JOINED,
        protocol=PROTOCOLS,
    )


def physics_baseline_outputs(name):
    return expand(f"{RESULTS}/baselines/{{protocol}}/{name}", protocol=PROTOCOLS)


# Keys of a classifier section that choose what it trains on, not how it is built: the CNN may
# train on fewer measured percentages and repeats than hybrid lists (its fits are costly).
from condmon.classifiers import SELECTION_KEYS


def classifier_params(name):
    return {
        k: v for k, v in config["classifiers"][name].items() if k not in SELECTION_KEYS
    }


def classifier_selection(name):
    """measured_percent / repeats of classifiers.<name> (None = all of hybrid's), checked here
    so a bad subset fails before any job runs."""
    section = config["classifiers"][name]
    selection = {
        "measured_percent": section.get("measured_percent"),
        "repeats": section.get("repeats"),
    }
    percents = selection["measured_percent"]
    if percents is not None and not set(percents) <= set(
        config["hybrid"]["measured_percent"]
    ):
        raise ValueError(
            f"classifiers.{name}.measured_percent: {sorted(set(percents))} must be "
            f"among hybrid.measured_percent {config['hybrid']['measured_percent']}"
        )
    if (
        selection["repeats"] is not None
        and selection["repeats"] > config["hybrid"]["repeats"]
    ):
        raise ValueError(
            f"classifiers.{name}.repeats: {selection['repeats']} is more than "
            f"hybrid.repeats ({config['hybrid']['repeats']})"
        )
    return {key: value for key, value in selection.items() if value is not None}


for _name in CLASSIFIERS:
    classifier_selection(_name)


def calibration_measured():
    """What the calibrations read: a bench's healthy records (`measured_healthy`), so they start
    while the bench still makes its fault records, or the measured table."""
    if EARLY_CALIBRATION:
        return f"{RESULTS}/measured/healthy.parquet"
    return f"{RESULTS}/measured/signals.parquet"


def measured_inputs(wildcards):
    """The system's measured files (a signal table, a folder of records), or every bench part."""
    return SYSTEM.measured_files() + expand(
        f"{RESULTS}/measured/parts/{{part}}.parquet", part=MEASURED_PARTS
    )


def data_source():
    return SYSTEM.data_source()


FEATURE_FAMILIES = config["features"]["kind"].split(
    "+"
)  # e.g. spectrum+order: both families


def statistical_feature_params():
    """features.statistical; None without the statistical family, so its settings never rerun
    another run's features."""
    if "statistical" not in FEATURE_FAMILIES:
        return None
    statistical = dict(config["features"]["statistical"])
    # the lines a defect modulates (the envelope features read them): in the settings the features
    # jobs and a packaged model take alike
    sidebands = SYSTEM.defect_sidebands()
    if sidebands:
        statistical["line_sidebands"] = dict(sidebands)
    return statistical


def feature_threads():
    """The features jobs' threads: every core of the run where a chosen family of the system's
    spreads its segments over them (`SystemFamily.parallel`), else one,
    so a family that cannot use them never holds the other jobs back."""
    own = SYSTEM.feature_families()
    chosen = [own[family] for family in FEATURE_FAMILIES if family in own]
    if any(family.parallel for family in chosen):
        return workflow.resource_settings.cores or 1
    return 1


def system_family_params():
    """{family: features.<family> plus what the system adds} of the system's own feature families
    in features.kind; None without any, so a system edit never
    reruns another run's features."""
    own = SYSTEM.feature_families()
    chosen = [family for family in FEATURE_FAMILIES if family in own]
    if not chosen:
        return None
    return {
        family: dict(
            config["features"].get(family) or {}, **SYSTEM.feature_family_params(family)
        )
        for family in chosen
    }


def final_outputs():
    return [
        *calibration_outputs("params.json").values(),
        f"{RESULTS}/report/accuracy.csv",
        f"{RESULTS}/report/summary.json",
        f"{RESULTS}/report/mlflow_run.json",
        f"{RESULTS}/report/mlflow_plots.json",  # the report's plots in the MLflow run
        f"{RESULTS}/report/pages/tables",  # what `snakemake --report` shows
        # requested, so a config without its packaged models reruns track (Snakemake checks
        # only the requested outputs of a job for being missing)
        f"{RESULTS}/models/{config_hash}",
    ]


# Recorded with the MLflow runs so a comparison can group runs of the same config.
from condmon.signals import config_hash as _config_hash

# The run's config: all but the predict_* keys (what a model is applied to changes no run).
RUN_CONFIG = {
    key: value for key, value in config.items() if not key.startswith("predict_")
}
config_hash = _config_hash(RUN_CONFIG)


def config_keys(section, prefix=""):
    """Every leaf of a config section as 'dotted.key=value'. Unpacked into a rule's params (one
    param each) they rerun the job on any change, as the section as one param would, and the rerun
    reason names the changed keys: Snakemake prints a changed param whole, before and now.
    """
    if isinstance(section, dict) and section:
        return [
            leaf
            for key in sorted(section)
            for leaf in config_keys(section[key], f"{prefix}{key}.")
        ]
    return [f"{prefix.rstrip('.')}={section!r}"]


def run_config(wildcards, output):
    """The run's config for a script: a function of the output, so Snakemake never compares or
    prints it (the rule's config_keys params rerun the job)."""
    return RUN_CONFIG


# features.healthy_reference: each machine's features against its own healthy reference
# (condmon/reference.py). Off, no job gets its params or the reference table: the jobs are those
# of a run without the key.
HEALTHY_REFERENCE = config["features"]["healthy_reference"]
REFERENCE_SEGMENTS = (
    HEALTHY_REFERENCE["simulated_segments"] if HEALTHY_REFERENCE["enabled"] else 0
)


def healthy_reference_params(source):
    """The features job's {"healthy_reference": ...} param for `source` (measured or simulated)."""
    if not HEALTHY_REFERENCE["enabled"]:
        return {}
    params = dict(
        source=source,
        healthy_state=SYSTEM.healthy_state,
        reference_segments=REFERENCE_SEGMENTS,
    )
    if source == "measured":  # the calibration set per condition
        params.update(condition=CONDITION, reserve=config["calibration"]["reserve"])
    else:  # each sample's healthy twin
        params.update(segments_per_sample=config["simulation"]["segments_per_sample"])
    return {"healthy_reference": params}


def measured_reference_output():
    """The measured features job's reference table, only with the reference on; with a system
    family that takes its reference itself (a waveform, not a mean feature), that family's
    references too."""
    if not HEALTHY_REFERENCE["enabled"]:
        return {}
    outputs = {"reference": f"{RESULTS}/features/measured_reference.parquet"}
    own = SYSTEM.feature_families()
    if any(
        f in own and own[f].references for f in config["features"]["kind"].split("+")
    ):
        outputs["family_references"] = (
            f"{RESULTS}/features/measured_family_references.parquet"
        )
        # ... and where on the machine each measured segment's change sits
        outputs["fault_locations"] = f"{RESULTS}/features/measured_fault_locations.csv"
        # ... and how each measured segment's shaft angle was found
        outputs["shaft_tracking"] = f"{RESULTS}/features/measured_shaft_tracking.csv"
    return outputs


def measured_fault_locations_input():
    """The report's inputs of where on the machine each measured segment's change sits and how
    its shaft angle was found, where a feature family locates faults."""
    output = measured_reference_output()
    return {
        key: output[key]
        for key in ("fault_locations", "shaft_tracking")
        if key in output
    }


def measured_family_references_input():
    """The simulated features job's input of the measured family references (the residual
    signatures' fixed tones, which every simulated segment loses as the measured ones do).
    """
    output = measured_reference_output()
    return (
        {"family_references": output["family_references"]}
        if "family_references" in output
        else {}
    )


# hybrid.simulated_validation_share > 0: the split table also lists the simulated records held out
# as the simulated validation set, so the hybrid jobs read the simulated record list and the train
# jobs score them. At 0 (default) neither gets that input, param or output: the jobs are those of
# a run without the key.
SIMULATED_VALIDATION_SHARE = config["hybrid"]["simulated_validation_share"]


# -- the report rule (report.smk) ------------------------------------------------------------


def upstream_benchmarks():
    """{rule: the benchmark file of each of its jobs} of every job before the report (from the
    rules' `benchmark:` patterns), so the report's job timings cover exactly this run's jobs. The
    track job runs beside the report."""
    return {
        "measured_part": expand(rules.measured_part.benchmark, part=MEASURED_PARTS),
        "measured": [rules.measured.benchmark],
        **(
            {"measured_healthy": [rules.measured_healthy.benchmark]}
            if EARLY_CALIBRATION
            else {}
        ),
        "calibrate": expand(rules.calibrate.benchmark, variant=CALIBRATIONS),
        **(
            {
                "calibrate_state": expand(
                    rules.calibrate_state.benchmark, state=STATE_CALIBRATIONS
                )
            }
            if STATE_CALIBRATIONS
            else {}
        ),
        "simulate": expand(
            rules.simulate.benchmark, health=HEALTH_STATES, point=POINTS, batch=BATCHES
        ),
        "features_measured": [rules.features_measured.benchmark],
        "features_simulated": [rules.features_simulated.benchmark],
        "hybrid": expand(rules.hybrid.benchmark, protocol=PROTOCOLS),
        "train": expand(
            rules.train.benchmark, classifier=CLASSIFIERS, protocol=PROTOCOLS
        ),
        "physics_baseline": expand(
            rules.physics_baseline.benchmark, protocol=PROTOCOLS
        ),
        **(
            {
                "joined": expand(
                    rules.joined.benchmark, classifier=JOINED, protocol=PROTOCOLS
                )
            }
            if JOINED
            else {}
        ),
    }


# The report stage's CSV tables, {name: file under report/}, from its sections' registry
# (condmon/report/registry.py: a new table is a section module and a line there), and those
# report_pages also shows as HTML tables.
from condmon.report.registry import tables as _report_tables

REPORT_TABLES = {table.name: table.file for table in _report_tables()}
REPORT_PAGES = [table.name for table in _report_tables() if table.page]


def plot_category(wildcards):
    """The report section of a plot or table of report/pages/, by its file name."""
    for prefix, category in (
        ("confusion", "Confusion matrices"),
        ("prediction_shares", "Confusion matrices"),
        ("spectra", "Calibration"),
        ("calibration", "Calibration"),
        ("job_timings", "Job timings"),
    ):
        if wildcards.name.startswith(prefix):
            return category
    return "Accuracy"


# -- the predict job (predict.smk) ------------------------------------------------------------
PREDICT_INPUT = config["predict_input"]
PREDICT_NAME = Path(PREDICT_INPUT).stem if PREDICT_INPUT else "unset"


def predict_inputs():
    if not PREDICT_INPUT:
        raise ValueError(
            "snakemake predict needs the measurements: name them with --config "
            "predict_input=PATH (a signal table, or a folder or file of the system's own records)"
        )
    # this run's model store unless predict_model names another model
    return {
        "data": PREDICT_INPUT,
        **({} if config["predict_model"] else {"models": rules.track.output.models}),
    }
