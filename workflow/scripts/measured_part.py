"""One part of a system's synthetic bench (`System.measured_parts`, e.g. one health state at one
speed)."""

from condmon.runlog import setup_logging
from condmon.signals import write_signal_table
from condmon.systems import load_system

log = setup_logging(snakemake)
p = snakemake.params
rows = load_system(p.system).measured_part_rows(snakemake.wildcards.part)
write_signal_table(rows, snakemake.output[0], config=dict(p.items()))
log.info("wrote %d rows", len(rows))
