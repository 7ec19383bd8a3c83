"""Stage logic of the condition-monitoring pipeline, importable without Snakemake."""
