# Simulation-trained condition monitoring of gear drivetrains: measured data in, calibrated
# exudyn model, simulated damage scenarios, features, hybrid training sets, classifiers, report.
# Run: snakemake --cores all [--configfile config/<run>.yaml]. Stages and files: ARCHITECTURE.md.
from snakemake.exceptions import WorkflowError

from condmon import python_version_error

# A wrong interpreter stops here, naming the Python the pins need, before any import can fail.
if python_version_error():
    raise WorkflowError(python_version_error())

from condmon.config import load_schema, validate_config


# The default run's config, unless the command line names one: a --configfile then replaces it
# whole (keys it lacks take the schema's defaults). Merging would leak the default run's keys into
# another run, e.g. the gear model's calibration bounds into a bearing-rig run.
if not workflow.config_settings.configfiles:

    configfile: "config/config.yaml"


# Every key is checked (and defaults filled) before any job is scheduled.
validate_config(config, load_schema(workflow.source_path("config/schema.yaml")))


include: "workflow/rules/common.smk"
include: "workflow/rules/measured.smk"
include: "workflow/rules/calibrate.smk"
include: "workflow/rules/simulate.smk"
include: "workflow/rules/features.smk"
include: "workflow/rules/hybrid.smk"
include: "workflow/rules/train.smk"
include: "workflow/rules/report.smk"


rule all:
    input:
        final_outputs(),
    default_target: True
