"""The measured signal table: the virtual bench's parts merged, the user's table validated, or
the CWRU .mat files of measured_dir ingested; plus records.csv (what was kept, what was left
out and why)."""
import pandas as pd

from condmon.atomic import write_text
from condmon.cwru import cwru_rows
from condmon.measured import read_user_table_checked
from condmon.runlog import setup_logging
from condmon.signals import read_signal_table, write_signal_table

log = setup_logging(snakemake)
p = snakemake.params
if p.source == "cwru":
    cwru = p.cwru
    ingest = cwru_rows(p.measured_dir, task=cwru["task"], channels=tuple(cwru["channels"]),
                       fs_hz=cwru["fs_hz"], segment_length=cwru["segment_length"],
                       manifest=cwru["manifest"], on_bad_record=p.on_bad_record)
    frame = pd.DataFrame(ingest.rows)
    records = pd.concat([ingest.records.assign(status="kept", reason=""),
                         ingest.excluded.assign(status="left out")], ignore_index=True)
elif p.source == "measured":
    frame, skipped = read_user_table_checked(snakemake.input[0], p.health_states, p.channels, p.output_rate_hz,
                                             p.segment_seconds, on_bad_record=p.on_bad_record)
else:
    frame = pd.concat([read_signal_table(path, allowed_sources=("virtual_bench",)) for path in snakemake.input],
                      ignore_index=True)
if p.source != "cwru":
    records = (frame[["record_id", "health_state", "speed_rpm", "load"]].drop_duplicates("record_id")
               .assign(status="kept", reason=""))
if p.source == "measured":
    records = pd.concat([records, skipped.assign(status="left out")], ignore_index=True)
write_signal_table(frame, snakemake.output[0], config=dict(p.items()))
write_text(records.to_csv(index=False), snakemake.output.records)
log.info("%s: %d records, %d segments, health states %s", p.source, frame["record_id"].nunique(),
         len(frame.drop_duplicates(["record_id", "segment"])), sorted(frame["health_state"].unique()))
left_out = records[records["status"] != "kept"]
for row in left_out.itertuples():
    log.warning("left out %s: %s", getattr(row, "file", row.record_id), row.reason)
