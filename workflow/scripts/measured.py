"""The measured signal table (the system's records: a bench's parts merged, the user's table
validated, or the system's own record files), plus records.csv (what was kept, what was
left out and why); or a bench's healthy parts merged (`measured_healthy`)."""

from condmon.atomic import write_text
from condmon.runlog import setup_logging
from condmon.signals import write_signal_table
from condmon.systems import load_system

log = setup_logging(snakemake)
p = snakemake.params
system = load_system(p.system)
inputs = list(snakemake.input)
parts = inputs[len(inputs) - p.parts :] if p.parts else []
files = inputs[: len(inputs) - p.parts]
frame, records = system.read_measured(files, parts, list(p.channels), p.on_bad_record)
write_signal_table(frame, snakemake.output[0], config=dict(p.items()))
if "records" in snakemake.output.keys():  # not for `measured_healthy`'s healthy records alone
    write_text(records.to_csv(index=False), snakemake.output.records)
log.info(
    "%s system: %d records, %d segments, health states %s",
    system.name,
    frame["record_id"].nunique(),
    len(frame.drop_duplicates(["record_id", "segment"])),
    sorted(frame["health_state"].unique()),
)
for row in records[records["status"] != "kept"].itertuples():
    log.warning("left out %s: %s", getattr(row, "file", row.record_id), row.reason)
