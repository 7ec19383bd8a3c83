# The workflow's entry: `snakemake --cores all [--configfile config/<run>.yaml]` in this folder.
# The pipeline itself is workflow/Snakefile (where the Snakemake workflow catalog's standardized
# usage looks for it, with its rules in workflow/rules/); this file only includes it.


include: "workflow/Snakefile"


# An include drops the included file's default target; the pipeline's is its rule `all`.
workflow.default_target = "all"
