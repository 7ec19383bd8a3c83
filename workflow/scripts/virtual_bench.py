"""Records of the virtual bench (synthetic) for one health state and speed."""
from condmon.measured import virtual_bench_rows
from condmon.runlog import setup_logging
from condmon.signals import write_signal_table

log = setup_logging(snakemake)
p = snakemake.params
rows = virtual_bench_rows(p.model, p.bench, [snakemake.wildcards.health], [float(snakemake.wildcards.speed)],
                          p.numerics, p.segment_seconds)
write_signal_table(rows, snakemake.output[0], config=dict(p.items()))
log.info("wrote %d rows", len(rows))
