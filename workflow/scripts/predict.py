"""Snakemake script: a model applied to a signal table or the system's own records -> predictions.

`snakemake` is injected by Snakemake's script directive. The logic lives in condmon.predict.
"""

import sys

from condmon.predict import PredictError, load_model, predict, read_input, write_outputs
from condmon.runlog import setup_logging
from condmon.signal_model import UnsupportedRecords

log = setup_logging(snakemake)  # to snakemake.log[0]
source = snakemake.params.model or snakemake.input.models
try:
    model, origin = load_model(str(source), snakemake.params.tracking_uri)
    frame, reader_records = read_input(snakemake.input.data, model)
    results = predict(model, frame)
    write_outputs(results, model, origin, snakemake.output[0], reader_records)
except (PredictError, UnsupportedRecords) as error:  # named: the record or the model at fault
    log.error("%s", error)
    sys.exit(1)
summary = results["summary"]
log.info(
    "%s: %d records, %d fault, by %s",
    snakemake.input.data,
    len(summary),
    (summary["status"] == "fault").sum(),
    origin["source"],
)
