"""Snakemake script: the run's full config (the config files with the schema's defaults filled
in) -> report/config.yaml, linked from the report's pages.

`snakemake` is injected by Snakemake's script directive.
"""

import yaml

from condmon.atomic import write_text
from condmon.runlog import setup_logging

log = setup_logging(snakemake)  # to snakemake.log[0]
write_text(yaml.safe_dump(dict(snakemake.params.config), sort_keys=True), snakemake.output[0])
log.info("wrote the run's config to %s", snakemake.output[0])
