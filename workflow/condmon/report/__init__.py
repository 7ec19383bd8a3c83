"""The report stage: tables, summary.json and plots from the train and calibration outputs, in
sections, and the report's pages.

Reads only the files of the stage contracts (train/<classifier>/<protocol>/metrics.csv and
predictions.parquet, calibration/<calibration variant>/params.json, spectra.parquet,
history.parquet, and the optional inputs of `inputs.ReportInputs`) and writes summary.json, the
tables the outputs name and plots/*.png (see condmon.plots).

- `inputs`: ReportInputs, what the report reads and where it writes;
- `write.write_report`: a loop over `registry.SECTIONS`, each section a module with a `SECTION`
  (`section.Section`: the inputs it reads and requires, its tables, its summary.json keys);
- `context.Report`: the inputs read once and what several sections share; `loading` and
  `aggregate` the readers and aggregates they use;
- the sections, in the registry's order: `accuracy` (accuracy.csv, summary.json's head),
  `prediction_shares` (with the confusion matrices), `calibration`, `stages` (simulation,
  measured records, simulated validation), `timings` (job_timings.csv), `evaluation_tables`
  (evaluation.csv, evaluation_summary.csv), `ceiling` (measured separability),
  `signatures` (fault signatures), `gain` (simulation gain plot), `physics`
  (physics_baselines.csv), `conditions` (per-condition plots), `headline` (headline.csv),
  `recall_per_record`;
- `pages`: the report stage's files as what `snakemake --report` shows (its own job).

A new table is one module with a SECTION and one line in registry.SECTIONS: report.smk's outputs
and the report pages' tables follow from `registry.tables()`.
"""
