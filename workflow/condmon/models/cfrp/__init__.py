"""Carbon-fibre laminate shafts of the CFRP rig (`system: cfrp`)."""
