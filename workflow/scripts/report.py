"""Snakemake script: train metrics/predictions + calibration -> report/accuracy.csv,
summary.json and plots/. The logic lives in condmon.report.

`snakemake` is injected by Snakemake's script directive.
"""
from condmon.report import write_report
from condmon.runlog import setup_logging

log = setup_logging(snakemake)  # to snakemake.log[0]
# One calibration per variant, the simulation's first: {variant: path}.
calibrations = list(snakemake.params.calibrations)


def calibration_files(kind):
    return {m: snakemake.input[f"calibration_{kind}_{m}"] for m in calibrations}


summary = write_report(
    metrics_paths=list(snakemake.input.metrics),
    predictions_paths=list(snakemake.input.predictions),
    calibration_params=calibration_files("params"),
    calibration_spectra=calibration_files("spectra"),
    calibration_history=calibration_files("history"),
    accuracy_path=snakemake.output.accuracy,
    summary_path=snakemake.output.summary,
    plots_dir=snakemake.output.plots,
    run_name=snakemake.params.run_name,
    data_source=snakemake.params.data_source,
    confusion_percent=list(snakemake.params.get("confusion_percent", [0])),
    simulation_reports=list(snakemake.input.simulation_reports),
    baseline_paths=list(snakemake.input.measured_only),
    baseline_prediction_paths=list(snakemake.input.measured_only_predictions),
    measured_records=snakemake.input.measured_records,
    record_recall_path=snakemake.output.recall_per_record,
    healthy_state=snakemake.params.get("healthy_state"),
    benchmarks={rule: list(snakemake.input[f"benchmarks_{rule}"]) for rule in snakemake.params.benchmarked_rules},
    job_timings_path=snakemake.output.get("job_timings"),
    bench_effects=list(snakemake.params.get("bench_effects", [])),
    prediction_shares_path=snakemake.output.get("prediction_shares"),
    simulated_validation_paths=list(snakemake.input.get("simulated_validation", [])),
    measured_features_path=snakemake.input.measured_features,
    condition=snakemake.params.condition,
    design_records=list(snakemake.params.design_records),
    design_specimens=list(snakemake.params.design_specimens),
    evaluation_path=snakemake.output.evaluation,
    evaluation_summary_path=snakemake.output.evaluation_summary,
    physics_paths=list(snakemake.input.physics_baselines),
    physics_baselines_path=snakemake.output.physics_baselines,
    headline_path=snakemake.output.headline,
)
log.info("report of run %s: %d result rows, %d plots", summary["run_name"],
         len(summary["results"]), len(summary["plots"]))
