"""Snakemake script: the report stage's tables, plots, headline and the run's config ->
report/pages/ (HTML tables, what `snakemake --report` shows). The logic lives in
condmon.report.pages.

`snakemake` is injected by Snakemake's script directive.
"""

import json
from pathlib import Path

from condmon.report.pages import write_pages
from condmon.runlog import setup_logging

log = setup_logging(snakemake)  # to snakemake.log[0]
inputs = snakemake.input
# named by the rule's input keys (no params of their own: the details pane shows the params)
CALIBRATION = "calibration_params_"
calibrations = {
    key[len(CALIBRATION) :]: inputs[key] for key in inputs.keys() if key.startswith(CALIBRATION)
}
tables = {
    key: inputs[key]
    for key in inputs.keys()
    if key not in ("headline", "plots", "config", "summary") and not key.startswith(CALIBRATION)
}
summary = json.loads(Path(inputs.summary).read_text())
protocols = summary["protocols"]
pages = Path(snakemake.output.tables).parent  # report/pages/: tables/, plots/, the files
names = write_pages(
    tables,
    inputs.headline,
    calibrations,
    inputs.plots,
    inputs.config,
    pages,
    protocols,
    bench_differences=summary["data_source"].get("bench_differences", ()),
)
log.info("report pages of run %s: %d tables in %s", snakemake.params.run_name, len(names), pages)
