"""Snakemake script: train metrics/predictions + calibration -> report/summary.json, plots/ and
the registered sections' tables (accuracy.csv, headline.csv, ...: condmon.report.registry, the
rule's outputs but summary and plots). The logic lives in condmon.report; this script only gathers
its inputs (condmon.report.inputs) from the rule's input, params and output.

`snakemake` is injected by Snakemake's script directive.
"""

from condmon.report.inputs import (
    CalibrationOutputs,
    EvaluationInputs,
    ReportInputs,
    ReportOutputs,
    RunIdentity,
    StageRecords,
    TrainOutputs,
)
from condmon.report.write import write_report
from condmon.runlog import setup_logging

log = setup_logging(snakemake)  # to snakemake.log[0]
inputs, params, output = snakemake.input, snakemake.params, snakemake.output


def calibration_files(kind):
    """{calibration variant: its file}, the simulation's variant first (params.calibrations)."""
    return {m: inputs[f"calibration_{kind}_{m}"] for m in params.calibrations}


summary = write_report(
    ReportInputs(
        run=RunIdentity(
            run_name=params.run_name,
            data_source=params.data_source,
            healthy_state=params.get("healthy_state"),
            bench_differences=params.get("bench_differences", []),
            state_models=params.get("state_models", []),
        ),
        train=TrainOutputs(
            metrics=inputs.metrics,
            predictions=inputs.predictions,
            measured_only=inputs.measured_only,
            physics=inputs.physics_baselines,
            physics_info=inputs.get("physics_baseline_info", []),
            simulated_validation=inputs.get("simulated_validation", []),
            measured_only_predictions=inputs.measured_only_predictions,
            coverage=inputs.get("coverage", []),
        ),
        calibration=CalibrationOutputs(
            params=calibration_files("params"),
            spectra=calibration_files("spectra"),
            history=calibration_files("history"),
            states={
                state: inputs[f"state_calibration_{state}"]
                for state in params.get("state_models", [])
            },
            state_histories={
                state: inputs[f"state_history_{state}"] for state in params.get("state_models", [])
            },
        ),
        evaluation=EvaluationInputs(
            measured_features=inputs.measured_features,
            simulated_features=inputs.get("simulated_features"),
            condition=params.condition,
            design_records=params.design_records,
            design_specimens=params.design_specimens,
            unmodelled=params.get("unmodelled", {}),
            calibration_set=params.get("calibration_set"),
            fault_locations=inputs.get("fault_locations"),
            shaft_tracking=inputs.get("shaft_tracking"),
            confusion_percent=params.get("confusion_percent", [0]),
        ),
        upstream=StageRecords(
            simulation_reports=inputs.simulation_reports,
            measured_records=inputs.measured_records,
            benchmarks={
                rule: tuple(inputs[f"benchmarks_{rule}"]) for rule in params.benchmarked_rules
            },
            cores=getattr(snakemake.resources, "run_cores", None),
        ),
        outputs=ReportOutputs(
            summary=output.summary,
            plots=output.plots,
            tables={
                name: output[name] for name in output.keys() if name not in ("summary", "plots")
            },
        ),
    )
)
log.info(
    "report of run %s: %d result rows, %d plots",
    summary["run_name"],
    len(summary["results"]),
    len(summary["plots"]),
)
