"""The contract every registered system passes (gear, bearing and the toy of tests/toy_system.py),
the registry, and the proofs that a system is one folder: the toy runs the smoke pipeline, and the
bearing system runs on another rig's signal table.

Contract: finite signals of its channels at its rate for every health state; the same seed gives
the same signal; a sample's parameters round-trip through JSON; a diverging sample raises the one
SimulationError, and a calibration scores such a candidate and goes on; its health states and
features agree with the config.
"""

import gc
import json
import os
import re
import shutil

import numpy as np
import pandas as pd
import pytest
import yaml

from conftest import ROOT, config_file, config_of
from condmon.calibrate import FAILED_COST, Bound, Calibrator, SpectrumModel
from condmon.config import ConfigError
from condmon.features import compute_feature_table
from condmon.models.numerics import SimulationError
from condmon.signals import make_rows
from condmon.systems import get_system, system_class
from condmon.systems.base import source_digest

TOY_MODULE = str(ROOT / "tests" / "toy_system.py")


def toy_config(run_name="toy-smoke") -> dict:
    """The toy's smoke config: every stage at tiny sizes."""
    return {
        "run_name": run_name,
        "system": "toy",
        "system_modules": [TOY_MODULE],
        "calibration": {
            "strategy": "per_law",
            "population": 4,
            "generations": 2,
            "sim_seconds": 0.5,
            "resolution_hz": 8.0,
        },
        "simulation": {"samples_per_state": 4, "samples_per_job": 4},
        "features": {"spectrum": {"f_min_hz": 0.0, "f_max_hz": 200.0, "resolution_hz": 4.0}},
        "hybrid": {
            "measured_percent": [0, 100],
            "repeats": 1,
            "protocols": ["record_split", "condition_holdout"],
        },
        "classifiers": {"cnn": {"enabled": False}},
    }


CONFIGS = {
    "gear": lambda: config_of(".test/config/smoke.yaml"),
    "bearing": lambda: config_of(".test/config/cwru-smoke.yaml"),
    "cfrp": lambda: config_of(".test/config/cfrp-smoke.yaml"),
    "toy": lambda: config_of(toy_config()),
}


# the bearing and CFRP rigs' simulations take seconds each: their contract cases are slow
SLOW_SYSTEMS = {"bearing", "cfrp"}


@pytest.fixture(
    scope="module",
    params=[
        pytest.param(name, marks=pytest.mark.slow) if name in SLOW_SYSTEMS else name
        for name in sorted(CONFIGS)
    ],
)
def system_and_config(request):
    config = CONFIGS[request.param]()
    return get_system(config), config


def one_sample(system, config, health_state, seed=7):
    calibrated = system.nominal_calibration(config["calibration"]["parameters"])
    parameters = system.sample_parameters(
        calibrated, health_state, np.random.default_rng(seed), config["simulation"]
    )
    duration = 2 * system.segment_length / system.output_rate_hz
    return parameters, duration


def test_every_health_state_gives_finite_signals_of_its_channels_at_its_rate(system_and_config):
    system, config = system_and_config
    assert (
        system.health_states == list(dict.fromkeys(system.health_states))
        and len(system.health_states) >= 2
    )
    for health in system.health_states:
        parameters, duration = one_sample(system, config, health)
        signals = system.simulate_sample(parameters, health, system.speeds_rpm[0], duration, seed=3)
        assert sorted(signals) == sorted(system.channels), health
        for name, signal in signals.items():
            assert len(signal) == int(round(duration * system.output_rate_hz)), (health, name)
            assert np.isfinite(signal).all() and np.std(signal) > 0, (health, name)


def test_same_seed_same_signal_and_parameters_round_trip_through_json(system_and_config):
    system, config = system_and_config
    health = system.health_states[-1]
    parameters, duration = one_sample(system, config, health)
    again, _ = one_sample(system, config, health)
    assert again == parameters
    through_json = json.loads(json.dumps(parameters))
    assert through_json == parameters
    speed = system.speeds_rpm[-1]
    first = system.simulate_sample(parameters, health, speed, duration, seed=11)
    second = system.simulate_sample(through_json, health, speed, duration, seed=11)
    for name in first:
        np.testing.assert_array_equal(first[name], second[name])


def _resident_mb() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


@pytest.mark.slow  # seven runs of a segment each
@pytest.mark.skipif(
    not os.path.exists("/proc/self/statm"), reason="needs Linux /proc to read the resident memory"
)
def test_repeated_runs_do_not_keep_memory(system_and_config):
    # a batch job or a calibration worker runs hundreds of samples in one process: exudyn keeps a
    # run's system (items, stored sensor data) until its container is reset, 3-4 MB per 0.1-s gear run
    system, config = system_and_config
    parameters, _ = one_sample(system, config, system.healthy_state)
    duration = system.segment_length / system.output_rate_hz

    # A leak grows in every pair of runs; a one-off growth does not (in a long test session the
    # allocator once kept a freed 4.4 MB buffer resident, in either of two intervals): so the
    # least growth over three pairs of runs is what must stay small.
    def growth_over_two_runs() -> float:
        before = _resident_mb()
        for seed in range(2):
            system.simulate_sample(
                parameters, system.healthy_state, system.speeds_rpm[0], duration, seed=seed
            )
        gc.collect()
        return _resident_mb() - before

    system.simulate_sample(
        parameters, system.healthy_state, system.speeds_rpm[0], duration, seed=3
    )  # warm-up
    gc.collect()
    assert min(growth_over_two_runs() for _ in range(3)) < 4.0


def test_a_diverging_sample_raises_the_one_simulation_error(system_and_config):
    system, config = system_and_config
    parameters, duration = one_sample(system, config, system.healthy_state)
    with pytest.raises(SimulationError):
        system.simulate_sample(
            system.diverging(parameters),
            system.healthy_state,
            system.speeds_rpm[0],
            duration,
            seed=1,
        )


class SometimesDiverging(SpectrumModel):
    """The system's own calibration spectra, but candidates with `diverge` > 0.5 run the system's
    diverging parameters: what a calibration meets when CMA-ES strays into an unstable corner."""

    def __call__(self, variant, values):
        values = dict(values)
        if values.pop("diverge") > 0.5:
            values = self.system.diverging(values)
        return super().__call__(variant, values)


def test_a_calibration_scores_a_diverging_candidate_and_goes_on(system_and_config):
    system, config = system_and_config
    spectrum = config["features"]["spectrum"]
    model = SometimesDiverging(
        system,
        system.speeds_rpm[:1],
        system.channels,
        spectrum,
        config["calibration"]["resolution_hz"],
        sim_seconds=system.segment_length / system.output_rate_hz,
        seed=1,
    )
    law = system.nominal_calibration([])["model_variant"]
    target = model(law, {"diverge": 0.0})
    calibrator = Calibrator(
        [Bound("diverge", 0.0, 1.0, False)],
        [law],
        strategy="per_law",
        population=6,
        generations=2,
        sigma0=0.5,
        seed=2,
        processes=2,
        initial={"diverge": 0.5},
    )
    best, history = calibrator.run(model, target)
    failed = history[history["cost"] >= FAILED_COST]
    assert len(history) == 12 and len(failed) >= 1 and (failed["error"] != "").all()
    assert (history["cost"] < FAILED_COST).sum() >= 1 and best["parameters"]["diverge"] <= 0.5


def test_health_states_and_features_agree_with_the_config(system_and_config):
    system, config = system_and_config
    assert set(config["features"]["channels"]) <= set(system.channels)
    assert system.healthy_state in system.health_states
    assert set(config["hybrid"]["measured_classes"]) <= set(system.health_states)
    rows = []
    for k, health in enumerate(system.health_states):
        parameters, duration = one_sample(system, config, health)
        signals = system.simulate_sample(parameters, health, system.speeds_rpm[0], duration, seed=k)
        rows += make_rows(
            f"r{k}",
            "simulated",
            health,
            system.speeds_rpm[0],
            system.sample_load(system.speeds_rpm[0], parameters),
            system.output_rate_hz,
            signals,
            segment_length=system.segment_length,
        )
    features = compute_feature_table(
        pd.DataFrame(rows), config["features"]["channels"], config["features"]["spectrum"]
    )
    assert len(features) == 2 * len(system.health_states)
    assert np.isfinite(features.iloc[:, 7:].to_numpy()).all()


def test_a_gear_rigs_own_sensors_name_its_channels():
    """Sensors as a rig has them (one axis, an angle, x and y) are the gear system's channels, and
    `features.channels` is checked against them; a direction the model cannot read is refused."""
    sensors = {"a1": {"housing": 0, "directions": ["y"]}, "a2": {"housing": 2, "directions": [30]}}
    own = {"model": {"sensors": sensors}, "features": {"channels": ["a1", "a2"]}}
    system = get_system(config_of(changes=own))
    assert system.channels == ["a1", "a2"]
    assert not [p for p in system.problems() if "channels" in p]
    wrong = {"model": {"sensors": {"a1": {"housing": 0, "directions": ["z"]}}}}
    with pytest.raises(ConfigError, match="sensors"):
        config_of(changes=wrong)


def test_model_stages_carry_the_model_digest(system_and_config):
    """The bench, calibrate and simulate jobs' param changes with the model code (so Snakemake
    reruns them); the stages that do not run the model do not carry it."""
    system, _ = system_and_config
    digest = system.model_digest()
    assert re.fullmatch(r"[0-9a-f]{64}", digest)
    for stage in ("bench", "calibrate", "simulate"):
        assert system.job_spec(stage)["model_digest"] == digest, stage
    for stage in ("measured", "features"):
        assert "model_digest" not in system.job_spec(stage), stage


def test_the_source_digest_follows_every_model_file(tmp_path):
    digest = source_digest.__wrapped__  # uncached: the files change under it
    (tmp_path / "sub").mkdir()
    (tmp_path / "model.py").write_text("stiffness = 1.0\n")
    (tmp_path / "schema.yaml").write_text("a: 1\n")
    deep, flat = digest(deep=(tmp_path,)), digest(flat=(tmp_path,))
    (tmp_path / "__pycache__").mkdir()
    (tmp_path / "__pycache__" / "model.py").write_text("compiled")
    assert digest(deep=(tmp_path,)) == deep
    (tmp_path / "sub" / "part.py").write_text("x = 2\n")
    assert digest(deep=(tmp_path,)) != deep
    assert digest(flat=(tmp_path,)) == flat
    (tmp_path / "model.py").write_text("stiffness = 2.0\n")
    assert digest(flat=(tmp_path,)) != flat
    # the same files elsewhere: the same digest
    moved = tmp_path.parent / (tmp_path.name + "-moved")
    shutil.copytree(tmp_path, moved)
    assert digest(deep=(moved,)) == digest(deep=(tmp_path,))


def test_a_systems_own_simulation_knob_reruns_its_simulations_only_and_never_another_systems():
    """The gear's per-sample perturbation lives in the gear's own section: the simulate rule's
    params are the system's job_spec("simulate") plus the shared simulation section, so an edit
    of it reruns the gear's simulations and what follows (not the bench or calibration), and a
    bearing (CWRU) run has no such knob at all: nothing of it reaches a bearing job. Here the
    job specs and configs; Snakemake's plans for the edits on the finished smoke runs, which
    every test that reads a run shares (conftest's `smoke`, `cwru_run`): test_pipeline.py
    (the gear's knob) and test_cwru_pipeline.py (a bearing run's own knob, and the gear's)."""
    gear = config_of(".test/config/smoke.yaml")
    assert "perturbation_sigma" not in gear["simulation"]
    system = get_system(gear)
    assert (
        system.job_spec("simulate")["config"]["model"]["variability"]["perturbation_sigma"] == 0.03
    )
    for stage in ("bench", "calibrate"):
        assert (
            "perturbation_sigma" not in system.job_spec(stage)["config"]["model"]["variability"]
        ), stage
    bearing = config_of(".test/config/cwru-smoke.yaml")
    assert "perturbation_sigma" not in json.dumps(
        get_system(bearing).job_spec("simulate")
    ) + json.dumps(bearing)
    with pytest.raises(ConfigError, match="unknown key model"):
        config_of(
            ".test/config/cwru-smoke.yaml", {"model": {"variability": {"perturbation_sigma": 0.05}}}
        )
    with pytest.raises(ConfigError, match="unknown key simulation.perturbation_sigma"):
        config_of(".test/config/cwru-smoke.yaml", {"simulation": {"perturbation_sigma": 0.05}})


def test_the_benchs_records_never_move_with_the_models_numerics():
    """The virtual bench stands for a real machine: it samples at virtual_bench.oversampling with
    its own integrator, steps and modal reduction, so the model's numerics of those names reach
    neither its job's params nor its records."""
    short = {"virtual_bench": {"records_per_state": 1, "record_seconds": 0.3}}
    records = []
    for numerics in (
        {"oversampling": 6},
        {
            "oversampling": 10,
            "modal_cutoff_hz": 3000.0,
            "integrator": "rk44",
            "steps_per_sensor_sample": 1,
        },
    ):
        system = get_system(config_of(".test/config/smoke.yaml", {**short, "numerics": numerics}))
        assert not {
            "oversampling",
            "integrator",
            "steps_per_sensor_sample",
            "modal_cutoff_hz",
        } & set(system.job_spec("bench")["config"]["numerics"])
        records.append(pd.DataFrame(system.measured_part_rows("healthy_450rpm")))
    coarse, fine = records
    pd.testing.assert_frame_equal(coarse.drop(columns="signal"), fine.drop(columns="signal"))
    assert np.array_equal(np.stack(coarse["signal"]), np.stack(fine["signal"]))
    finer = get_system(
        config_of(
            ".test/config/smoke.yaml",
            {**short, "virtual_bench": {**short["virtual_bench"], "oversampling": 12}},
        )
    )
    assert not np.allclose(
        np.stack(pd.DataFrame(finer.measured_part_rows("healthy_450rpm"))["signal"]),
        np.stack(records[0]["signal"]),
    )


def test_each_system_checks_its_own_costs_variants_and_bounds():
    """The costs, model variants and parameter checks are the system's: the shared layer names none."""
    with pytest.raises(
        ConfigError, match=r"calibration.cost: 'features_eq6' is not a cost of the gear system"
    ):
        config_of(".test/config/smoke.yaml", {"calibration": {"cost": "features_eq6"}})
    assert config_of(".test/config/cwru-smoke.yaml", {"calibration": {"cost": "features_eq6"}})
    with pytest.raises(
        ConfigError, match=r"calibration.parameters.restitution: bounds must lie in \(0, 1\]"
    ):
        config_of(
            ".test/config/smoke.yaml",
            {"calibration": {"parameters": {"restitution": {"low": 0.5, "high": 1.2}}}},
        )
    with pytest.raises(ConfigError, match="unknown key calibration.contact_laws"):
        config_of(".test/config/cwru-smoke.yaml", {"calibration": {"contact_laws": ["flores"]}})
    with pytest.raises(
        ConfigError, match=r"virtual_bench.faults.spall.face: \[start, end\] with start < end"
    ):
        config_of(
            ".test/config/smoke.yaml",
            {
                "virtual_bench": {
                    "faults": {
                        "spall": {
                            "form": "spall",
                            "depth": 2e-4,
                            "profile": [0.3, 0.6],
                            "face": [0.9, 0.1],
                        }
                    }
                }
            },
        )
    gear, bearing, toy = (get_system(CONFIGS[name]()) for name in ("gear", "bearing", "toy"))
    assert gear.model_variants({"contact_laws": ["flores", "gonthier"]}) == ["flores", "gonthier"]
    assert bearing.model_variants({}) == ["hertz"] and toy.model_variants({}) == [
        toy.nominal_variant
    ]
    with pytest.raises(ValueError, match="one model variant"):
        toy.simulate_healthy("flores", {}, toy.speeds_rpm[0], 0.1, seed=1)


def test_registry_errors_name_the_culprit():
    with pytest.raises(
        ValueError, match=r"unknown system 'turbine'; registered: \[.*'bearing'.*'gear'"
    ):
        system_class("turbine")
    with pytest.raises(ConfigError, match="unknown system 'turbine'"):
        config_of(".test/config/smoke.yaml", {"system": "turbine"})
    with pytest.raises(ConfigError, match="unknown key cwru"):  # another system's section
        config_of(".test/config/smoke.yaml", {"cwru": {"task": "location"}})
    with pytest.raises(ConfigError, match="no such file"):
        config_of(toy_config() | {"system_modules": [str(ROOT / "tests" / "no_such_system.py")]})


def shared_files() -> list:
    """The shared layer: every file of the workflow outside condmon/systems/ and condmon/models/,
    and the shared schema."""
    workflow = ROOT / "workflow"
    library = workflow / "condmon"
    return [
        workflow / "Snakefile",
        *sorted((workflow / "rules").glob("*.smk")),
        *sorted((workflow / "scripts").glob("*.py")),
        *sorted((workflow / "report").glob("*.rst")),
        *sorted(
            p
            for p in library.rglob("*.py")
            if p.relative_to(library).parts[0] not in ("systems", "models")
        ),
        ROOT / "config" / "schema.yaml",
    ]


def test_no_branch_on_a_system_name_outside_the_registry():
    """Rules, scripts and the stage library ask the system; only condmon/systems/ knows names."""
    pattern = re.compile(r"""(['"](gear|bearing|cfrp|cwru|toy)['"])|SYSTEM\s*==|\bsystem\s*==""")
    hits = [
        f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
        for path in shared_files()
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if pattern.search(line)
    ]
    assert hits == []


# Words of one rig or its model family. The shared layer speaks of systems, calibration and model
# variants, costs, defect orders; these belong in condmon/systems/ and models/. (`cfrp_eq4` and
# `helical_eq14` name the spectral costs after the studies that define them, so `cfrp` and
# `helical` are not listed.)
RIG_WORDS = (
    "mesh",
    "gear",
    "tooth",
    "teeth",
    "pinion",
    "helix",
    "housing",
    "bushing",
    "backlash",
    "spall",
    "laminate",
    "delamination",
    "bearing",
    "ball",
    "outer_race",
    "inner_race",
    "bpfo",
    "bpfi",
    "bsf",
    "ftf",
    "cwru",
    "skf",
    "6205",
    "6203",
    "restitution",
    "contact_law",
    "hertz",
    "perturbation_sigma",
    "features_eq6",
)
RIG_WORD = re.compile(
    r"(?<![a-z0-9])(" + "|".join(RIG_WORDS) + r")(?:s|es)?(?![a-z0-9])", re.IGNORECASE
)
# (file, word) -> why the word may stand there. Prose only (comments, docstrings, captions) unless
# the entry says `code`; an entry no longer needed fails the test too.
RIG_WORDS_ALLOWED = {
    ("workflow/condmon/hybrid.py", "cwru"): "prose: which system's condition is the load and has "
    "one healthy record per load (calibration set)",
    ("workflow/condmon/hybrid.py", "gear"): "prose: which system's condition is the speed",
    (
        "workflow/condmon/labels.py",
        "bearing",
        "code",
    ): "protocol label cites the study that defined segment_share",
    (
        "workflow/condmon/classifiers.py",
        "gear",
    ): "prose: cites the helical-gear study's CNN ensemble",
    ("workflow/condmon/cnn.py", "gear"): "prose: cites the helical-gear study",
    ("workflow/condmon/cnn.py", "tooth"): "prose: why the members plateaued on one class",
    ("workflow/condmon/selection.py", "bearing"): "prose: cites the bearing study's selection",
    ("workflow/condmon/stat_features.py", "bearing"): "prose: titles of the cited papers",
    ("workflow/condmon/stat_features.py", "cwru"): "prose: a cited paper's data set",
    ("config/schema.yaml", "cwru"): "comment: pdm-bench's split is named cwru_cross_load",
    ("config/schema.yaml", "gear", "code"): "the default run's system",
}


def python_words(text: str):
    """(kind, line, word) of every rig word in Python (or Snakemake) source: `code` in names and
    strings an expression uses, `prose` in comments and lone strings (docstrings)."""
    import io
    import tokenize

    tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    statement = [t for t in tokens if t.type not in (tokenize.NL, tokenize.COMMENT)]
    bounds = (tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT, tokenize.ENDMARKER)
    for i, token in enumerate(statement):
        if token.type == tokenize.STRING:
            before = statement[i - 1] if i else None
            after = statement[i + 1] if i + 1 < len(statement) else None
            lone = (before is None or before.type in bounds) and (
                after is None or after.type in bounds
            )
            kind = "prose" if lone else "code"
        elif token.type == tokenize.NAME:
            kind = "code"
        else:
            continue
        for match in RIG_WORD.finditer(token.string):
            yield kind, token.start[0], match.group(1).lower()
    for token in tokens:
        if token.type == tokenize.COMMENT:
            for match in RIG_WORD.finditer(token.string):
                yield "prose", token.start[0], match.group(1).lower()


def yaml_words(text: str):
    """(kind, line, word) of a YAML file: `code` in keys and values, `prose` in comments."""
    for n, line in enumerate(text.splitlines(), 1):
        content, _, comment = line.partition("#")
        for kind, part in (("code", content), ("prose", comment)):
            for match in RIG_WORD.finditer(part):
                yield kind, n, match.group(1).lower()


def rig_words(path):
    text = path.read_text()
    if path.suffix == ".yaml":
        return list(yaml_words(text))
    if path.suffix == ".rst":
        return [
            ("prose", n, m.group(1).lower())
            for n, line in enumerate(text.splitlines(), 1)
            for m in RIG_WORD.finditer(line)
        ]
    return list(python_words(text))


def rig_word_hits(files) -> tuple[list, set]:
    """Rig words outside the allowed ones, and the allowed entries that were used."""
    hits, used = [], set()
    for path in files:
        name = path.relative_to(ROOT).as_posix()
        for kind, line, word in rig_words(path):
            key = (name, word) if kind == "prose" else (name, word, "code")
            if key in RIG_WORDS_ALLOWED:
                used.add(key)
            else:
                hits.append(f"{name}:{line}: {word} ({kind})")
    return hits, used


def test_the_shared_layer_speaks_no_rigs_language(tmp_path):
    """No rig word (RIG_WORDS) outside condmon/systems/ and models/ beyond the allowed prose: the
    shared layer says "calibration variant", "model variant", "cost", "defect orders"."""
    hits, used = rig_word_hits(shared_files())
    assert hits == [], (
        "rig vocabulary in the shared layer (move it into the system):\n" + "\n".join(hits)
    )
    assert set(RIG_WORDS_ALLOWED) - used == set(), "allowed entries no longer needed"
    # the guard bites: a contact law named in the shared calibration, in code or in a comment
    copy = tmp_path / "workflow" / "condmon" / "calibrate.py"
    copy.parent.mkdir(parents=True)
    for line in (
        'law = values.pop("contact_law")\n',
        "# the contact law's restitution\n",
        'COSTS = ("cfrp_eq4", "features_eq6")\n',
        "simulation['perturbation_sigma']\n",
    ):
        copy.write_text((ROOT / "workflow" / "condmon" / "calibrate.py").read_text() + line)
        found = [kind for kind, _, _ in rig_words(copy)]
        assert found, line


# -- pipelines (minutes) ---------------------------------------------------------------------------
@pytest.mark.pipeline
def test_the_toy_system_runs_the_smoke_pipeline_to_its_report(tmp_path):
    from conftest import copy_project, snakemake

    workdir = copy_project(tmp_path / "project")
    (workdir / "toy.yaml").write_text(yaml.safe_dump(toy_config()))
    results = workdir / "results" / "toy-smoke"
    # up to the report (what is checked here); the MLflow tracking is the smoke run's to test
    snakemake(
        workdir,
        "--cores",
        "2",
        str((results / "report" / "summary.json").relative_to(workdir)),
        "--configfile",
        "toy.yaml",
    )
    accuracy = pd.read_csv(results / "report" / "accuracy.csv")
    assert (
        set(accuracy["protocol"]) == {"record_split", "condition_holdout"}
        and accuracy["accuracy"].between(0, 1).all()
    )
    calibration = json.loads((results / "calibration" / "rig" / "params.json").read_text())
    assert set(calibration["parameters"]) == {"stiffness", "damping"}
    simulated = pd.read_parquet(results / "features" / "simulated.parquet")
    assert (
        set(simulated["health_state"]) == {"healthy", "loose_mount"} and len(simulated) == 2 * 2 * 4
    )  # states x speeds x samples
    summary = json.loads((results / "report" / "summary.json").read_text())
    assert summary["data_source"]["kind"] == "virtual_bench"


def rig_signal_table(path, system, labels_by_defect, speeds_loads, records=2, seed=0):
    """A 'measured' table of another bearing rig: the rig model with the config's geometry at
    other values (stiffer contact, more noise, another transfer path), each record its own draw."""
    rng = np.random.default_rng(seed)
    rows = []
    for label in labels_by_defect:
        for speed, load in speeds_loads:
            for r in range(records):
                values = dict(
                    system.sample_parameters(
                        {"parameters": {"contact_stiffness": 1.1e10}}, label, rng, {}
                    )
                )
                values["noise_rms"] = 0.5
                signals = system.simulate_sample(
                    values,
                    label,
                    speed,
                    3 * system.segment_length / 12000.0,
                    int(rng.integers(2**31)),
                )
                rows += make_rows(
                    f"rig2-{label}-{speed:g}-{r}",
                    "measured",
                    label,
                    speed,
                    load,
                    12000.0,
                    signals,
                    segment_length=system.segment_length,
                )
    from condmon.signals import write_signal_table

    write_signal_table(rows, path)


@pytest.mark.pipeline
def test_a_bearing_run_from_another_rigs_signal_table(tmp_path):
    """Not CWRU: a 12-ball angular-contact bearing, labels of the user's own, loads of its own,
    read from a signal table; the smoke pipeline runs up to its report without an edit to the code."""
    from conftest import copy_project, snakemake

    labels = {
        "ok": {"defect": "none"},
        "outer": {"defect": "outer_race", "diameter_mm": [0.3, 0.6]},
        "inner": {"defect": "inner_race", "diameter_mm": [0.3, 0.6]},
    }
    config = config_file(".test/config/cwru-smoke.yaml")
    config.update(run_name="rig2-smoke", measured_table=str(tmp_path / "rig2.parquet"))
    config["bearing"].update(
        segment_length=2048,
        health_states=labels,
        healthy_state="ok",
        geometry={
            "n_balls": 12,
            "ball_diameter": 7.0e-3,
            "pitch_diameter": 46.0e-3,
            "contact_angle_deg": 15.0,
        },
        load_speeds=[[2.0, 1500.0], [5.0, 1450.0]],
    )
    config["rig"] = {"speeds_rpm": [1500, 1450]}
    config["hybrid"].update(
        protocols=["unseen_fault", "record_split"],
        measured_classes=["ok"],
        measured_percent=[0, 100],
    )
    config["classifiers"]["knn"]["enabled"] = (
        False  # the plumbing is the point; one classifier will do
    )
    config["simulation"].update(samples_per_state=2, samples_per_job=2)  # and two samples a state
    config["calibration"].update(sim_seconds=0.4)
    validated = config_of(json.loads(json.dumps(config)))
    rig_signal_table(
        tmp_path / "rig2.parquet", get_system(validated), labels, [(1500.0, 2.0), (1450.0, 5.0)]
    )
    workdir = copy_project(tmp_path / "project")
    (workdir / "rig2.yaml").write_text(yaml.safe_dump(config))
    results = workdir / "results" / "rig2-smoke"
    # up to the report (what is checked here); the MLflow tracking is the smoke runs' to test
    snakemake(
        workdir,
        "--cores",
        "2",
        str((results / "report" / "summary.json").relative_to(workdir)),
        "--configfile",
        "rig2.yaml",
    )
    summary = json.loads((results / "report" / "summary.json").read_text())
    assert summary["labels"][0] == "ok" and set(summary["labels"]) == set(labels)
    records = pd.read_csv(results / "measured" / "records.csv")
    assert (records["status"] == "kept").sum() == 12
    simulated = pd.read_parquet(results / "features" / "simulated.parquet")
    assert set(simulated["load"]) == {2.0, 5.0} and set(simulated["health_state"]) == set(labels)


@pytest.mark.slow
def test_the_default_profile_is_loaded():
    import subprocess
    import sys

    result = subprocess.run(
        [sys.executable, "-m", "snakemake", "-n", "--configfile", ".test/config/smoke.yaml"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    assert "Using workflow specific profile profiles/default" in result.stdout + result.stderr
    profile = yaml.safe_load((ROOT / "profiles" / "default" / "config.yaml").read_text())
    assert profile["rerun-incomplete"] and profile["show-failed-logs"]


def import_graph() -> dict:
    """{module: the condmon modules it imports}, lazy imports included, over workflow/condmon and
    its models/ (condmon.models), plus the registry's imports through importlib (each
    built-in system's module, by its import path in BUILT_IN)."""
    import ast

    from condmon.systems import BUILT_IN

    modules = {}
    for package, prefix in ((ROOT / "workflow" / "condmon", ("condmon",)),):
        for path in package.rglob("*.py"):
            parts = prefix + path.relative_to(package).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {}
    for name, path in modules.items():
        imported = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.ImportFrom)
                and node.module
                and node.module.startswith("condmon")
            ):
                imported.add(node.module)
                imported |= {f"{node.module}.{a.name}" for a in node.names}  # a submodule by name
            elif isinstance(node, ast.Import):
                imported |= {a.name for a in node.names if a.name.startswith("condmon")}
        graph[name] = {m for m in imported if m in modules and m != name}
    graph["condmon.systems"] |= {path.split(":")[0] for path in BUILT_IN.values()}
    return graph


def test_the_library_has_no_import_cycle():
    """Imports between condmon modules, lazy ones and the registry's importlib ones included, form
    no cycle (features <-> stat_features once did; config -> systems -> bearing.model -> config
    through importlib too); the physics models import nothing of the workflow above them."""
    graph = import_graph()
    assert graph["condmon.systems"] >= {"condmon.systems.bearing", "condmon.systems.gear"}
    assert "condmon.models.bearing.rig" in graph["condmon.systems.bearing"]
    # tracking reads the train tables and labels as the report does, never through the report
    assert not graph["condmon.labels"] and not any(
        m.split(".")[:2] == ["condmon", "report"] for m in graph["condmon.tracking"]
    )
    for name, imported in graph.items():
        if name.startswith("condmon.models"):
            assert all(m.startswith("condmon.models") for m in imported), (name, imported)
    state = {}

    def visit(name, trail):
        state[name] = "open"
        for other in sorted(graph[name]):
            assert state.get(other) != "open", f"import cycle: {' -> '.join(trail + [name, other])}"
            if other not in state:
                visit(other, trail + [name])
        state[name] = "done"

    for name in sorted(graph):
        if name not in state:
            visit(name, [])


def test_the_models_mirror_the_systems_that_use_them():
    """models/ holds one subpackage per system (models/gear used by systems/gear, ...) beside the
    modules several share (numerics, structure). A model imports no workflow module and no other
    system's subpackage; a system imports its own subpackage and those of the systems it builds on
    (cfrp on gear), the shared layer only the shared modules; pyproject.toml installs them all."""
    import tomllib

    from condmon.systems import BUILT_IN

    graph = import_graph()
    models = ROOT / "workflow" / "condmon" / "models"
    packages = {path.parent for path in models.rglob("__init__.py")} - {models}
    subpackages = {folder.name for folder in packages}
    assert subpackages and subpackages <= set(BUILT_IN), (
        f"models/ subpackages that are no system: {subpackages}"
    )

    def models_subpackage(module):  # "gear" for condmon.models.gear.mesh, None for a shared one
        parts = module.split(".")
        return (
            parts[2]
            if parts[:2] == ["condmon", "models"] and len(parts) > 2 and parts[2] in subpackages
            else None
        )

    def system_of_module(module):
        parts = module.split(".")
        return (
            parts[2]
            if parts[:2] == ["condmon", "systems"] and len(parts) > 2 and parts[2] in BUILT_IN
            else None
        )

    for name, imported in graph.items():
        if name.startswith("condmon.models"):
            allowed = {models_subpackage(name), None}
            assert all(m.startswith("condmon.models.") for m in imported), (
                f"{name} imports the workflow: {imported}"
            )
            assert {models_subpackage(m) for m in imported} <= allowed, (
                f"{name} imports another system's models: {imported}"
            )
    bases = {system: set() for system in BUILT_IN}  # the systems each system builds on
    for name, imported in graph.items():
        if system_of_module(name):
            bases[system_of_module(name)] |= {system_of_module(m) for m in imported} - {
                None,
                system_of_module(name),
            }
    assert bases["cfrp"] == {
        "gear"
    }  # the cfrp system is the gear system built from other parameters
    for name, imported in graph.items():
        if name.startswith("condmon.models"):
            continue
        system = system_of_module(name)
        allowed = ({system} | bases[system]) if system else set()
        used = {models_subpackage(m) for m in imported} - {None}
        assert used <= allowed, f"{name} imports the models of {sorted(used - allowed)}"
    assert "condmon.models.gear.drivetrain" in graph["condmon.systems.gear"]
    assert "condmon.models.cfrp.laminate" in graph["condmon.systems.cfrp.parameters"]

    on_disk = {
        ".".join(path.parent.relative_to(ROOT / "workflow").parts)
        for path in (ROOT / "workflow" / "condmon").rglob("__init__.py")
    }
    listed = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    assert set(listed) == on_disk, (
        f"pyproject.toml's packages differ from the folders: {set(listed) ^ on_disk}"
    )


RIG2_LABELS = {
    "ok": {"defect": "none"},
    "outer": {"defect": "outer_race", "diameter_mm": [0.3, 0.6]},
}


def rig2_config(table, protocols) -> dict:
    """cwru-smoke.yaml on a user's bearing table (labels ok / outer) with ``protocols``."""
    return config_of(
        ".test/config/cwru-smoke.yaml",
        {
            "measured_table": str(table),
            "hybrid": {"protocols": protocols},
            "bearing": {"health_states": RIG2_LABELS, "healthy_state": "ok"},
        },
    )


def rig2_table(path, specimens: dict | None) -> None:
    """Two loads, ok and two outer-race specimens of two sizes; with ``specimens`` ({record:
    (specimen, group)}) the optional columns a user's table may carry."""
    rng = np.random.default_rng(0)
    rows = []
    for load, speed in ((0.0, 1797.0), (1.0, 1772.0)):
        for record, label in (
            (f"ok-{load:g}", "ok"),
            (f"or-a-{load:g}", "outer"),
            (f"or-b-{load:g}", "outer"),
        ):
            rows += make_rows(
                record,
                "measured",
                label,
                speed,
                load,
                12000.0,
                {"DE": rng.normal(size=8192)},
                segment_length=4096,
            )
    frame = pd.DataFrame(rows)
    if specimens is not None:
        frame["specimen"] = frame["record_id"].map(lambda r: specimens.get(r, ("", ""))[0])
        frame["specimen_group"] = frame["record_id"].map(lambda r: specimens.get(r, ("", ""))[1])
    frame.to_parquet(path)


def test_a_protocol_the_measured_data_cannot_serve_is_refused_at_the_config_check(tmp_path):
    """specimen_holdout needs each fault record's specimen: the virtual bench has none, a user's
    table has them where it carries the columns specimen and specimen_group."""
    with pytest.raises(ConfigError) as bench:
        config_of(
            ".test/config/smoke.yaml",
            {"hybrid": {"protocols": ["record_split", "specimen_holdout"]}},
        )
    assert (
        "hybrid.protocols: specimen_holdout needs each measured fault record's specimen and specimen_group, "
        "and the gear system's virtual bench gives none"
    ) in str(bench.value)
    rig2_table(tmp_path / "plain.parquet", None)
    with pytest.raises(ConfigError) as plain:
        rig2_config(tmp_path / "plain.parquet", ["specimen_holdout"])
    assert (
        f"specimen_holdout needs each measured fault record's specimen and specimen_group, and the "
        f"measured_table {tmp_path / 'plain.parquet'} has no columns ['specimen', 'specimen_group']"
    ) in str(plain.value)
    rig2_config(tmp_path / "plain.parquet", ["record_split"])  # what it can serve
    # with the columns: served, and measured/records.csv carries them for the protocol
    specimens = {
        f"or-{s}-{load}": (f"outer-{s}", size)
        for s, size in (("a", "0.3"), ("b", "0.5"))
        for load in "01"
    }
    rig2_table(tmp_path / "specimens.parquet", specimens)
    system = get_system(rig2_config(tmp_path / "specimens.parquet", ["specimen_holdout"]))
    _, records = system.read_measured([system.measured_table], [], ["DE"], "stop")
    assert dict(zip(records["record_id"], zip(records["specimen"], records["specimen_group"]))) == {
        **specimens,
        "ok-0": ("", ""),
        "ok-1": ("", ""),
    }


def test_a_record_of_several_specimens_is_refused_naming_it(tmp_path):
    from condmon.measured import read_user_table_checked
    from condmon.signals import SignalTableError

    rig2_table(tmp_path / "mixed.parquet", {"or-a-0": ("outer-a", "0.3")})
    frame = pd.read_parquet(tmp_path / "mixed.parquet")
    frame.loc[(frame["record_id"] == "or-a-0") & (frame["segment"] == 1), "specimen"] = "outer-b"
    frame.to_parquet(tmp_path / "mixed.parquet")
    with pytest.raises(
        SignalTableError, match=r"mixed.parquet: record 'or-a-0' mixes several specimen values"
    ):
        read_user_table_checked(
            tmp_path / "mixed.parquet", ["ok", "outer"], ["DE"], 12000.0, 4096 / 12000.0
        )
