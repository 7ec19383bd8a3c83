"""Snakemake script: signal table(s) -> features table (band spectra, statistical features, a
system's own families, or several of these side by side).

`snakemake` is injected by Snakemake's script directive.
"""

import pandas as pd

from condmon.atomic import write_frame, write_text
from condmon.features import (
    FamilyInputs,
    compute_feature_table_from_files,
    feature_columns,
    write_feature_table,
)
from condmon import reference
from condmon.runlog import setup_logging
from condmon.systems import load_system

log = setup_logging(snakemake)  # to snakemake.log[0]

signal_paths = snakemake.input.signals
signal_paths = [signal_paths] if isinstance(signal_paths, str) else list(signal_paths)
channels = list(snakemake.params.channels)
spectrum = dict(snakemake.params.spectrum)
kind = getattr(snakemake.params, "kind", "spectrum")
statistical = dict(getattr(snakemake.params, "statistical", None) or {})
families = dict(
    getattr(snakemake.params, "families", None) or {}
)  # the system's own, with their params

# the system says where its envelope lines are (its defect orders), if it has any, and computes its own families
system = load_system(snakemake.params.system)
against = getattr(snakemake.params, "healthy_reference", None)
# the measured records' own references (a simulated run's families read what they share, e.g. fixed tones)
measured_references = getattr(snakemake.input, "family_references", None)
# the families' settings (the rule's params) apart from what they take at run time: the healthy
# reference (a family that takes every machine against it itself), the job's cores
inputs = FamilyInputs(
    healthy_reference=dict(against) if against else None,
    measured_references=pd.read_parquet(measured_references) if measured_references else None,
    processes=snakemake.threads,
)
settings = {
    "spectrum": spectrum,
    "statistical": statistical,
    **{family: dict(params) for family, params in families.items()},
}
frame = compute_feature_table_from_files(
    signal_paths,
    channels,
    kind,
    settings,
    system.defect_orders(),
    system.feature_families(),
    inputs,
)
names = feature_columns(frame)
referenced = list(
    frame.attrs.get("referenced_columns", ())
)  # a family that took its reference itself
family_references = frame.attrs.get("references")  # ... and its measured references, to package
fault_locations = frame.attrs.get(
    "fault_locations"
)  # ... and where on the machine each segment's change sits
shaft_tracking = frame.attrs.get("shaft_tracking")  # ... and how each segment's angle was found
frame.attrs = {}
config = {"channels": channels, "spectrum": spectrum, "kind": kind, "statistical": statistical}
config.update(
    families
)  # only with a system family, so the other families' config hash stays as it was

# features.healthy_reference: each machine's features against its own healthy reference (a
# family that subtracts its reference as a waveform has done so already: its own columns stay)
if against:
    config["healthy_reference"] = dict(against)
    levels = [name for name in names if name not in referenced]
    if against["source"] == "measured":
        table = reference.measured_reference(
            frame, levels, against["healthy_state"], against["condition"], dict(against["reserve"])
        )
        frame = reference.refer_measured(frame, levels, table, against["condition"])
        for message in reference.reference_length_mismatches(
            frame,
            against["healthy_state"],
            against["condition"],
            dict(against["reserve"]),
            int(against["reference_segments"]),
        ):
            log.warning(message)
        if "family_references" in snakemake.output.keys():
            write_frame(family_references, snakemake.output.family_references)
        if "fault_locations" in snakemake.output.keys():
            write_text(fault_locations.to_csv(index=False), snakemake.output.fault_locations)
        if "shaft_tracking" in snakemake.output.keys():
            write_text(shaft_tracking.to_csv(index=False), snakemake.output.shaft_tracking)
        write_frame(
            reference.reference_table(table, against["condition"]), snakemake.output.reference
        )
        log.info(
            "measured segments taken against the calibration set's mean at %s %s",
            against["condition"],
            sorted(table.index.tolist()),
        )
    else:
        before = frame["record_id"].nunique()
        frame = reference.refer_simulated(
            frame, levels, against["healthy_state"], int(against["segments_per_sample"])
        )
        log.info(
            "simulated samples taken against their healthy twins' last %s segment(s): %d of %d records kept",
            against["reference_segments"],
            frame["record_id"].nunique(),
            before,
        )
write_feature_table(frame, names, snakemake.output.features, kind=kind, config=config)
log.info("wrote %d segments x %d features to %s", len(frame), len(names), snakemake.output.features)
