"""The measured signal table: the virtual bench's parts merged, or the user's table validated."""
import pandas as pd

from condmon.measured import read_user_table
from condmon.runlog import setup_logging
from condmon.signals import read_signal_table, write_signal_table

log = setup_logging(snakemake)
p = snakemake.params
if p.source == "measured":
    frame = read_user_table(snakemake.input[0], p.health_states, p.channels, p.output_rate_hz, p.segment_seconds)
else:
    frame = pd.concat([read_signal_table(path, allowed_sources=("virtual_bench",)) for path in snakemake.input],
                      ignore_index=True)
write_signal_table(frame, snakemake.output[0], config=dict(p.items()))
log.info("%s: %d records, %d segments, health states %s", p.source, frame["record_id"].nunique(),
         len(frame.drop_duplicates(["record_id", "segment"])), sorted(frame["health_state"].unique()))
