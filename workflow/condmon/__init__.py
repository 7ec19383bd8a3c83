"""Stage logic of the condition-monitoring pipeline, importable without Snakemake."""

import platform
import sys

# environment.txt (one set of pins for all three: every pinned version has wheels, or is pure
# Python, for each; tests/test_envs.py checks that they resolve) and the rules' conda environments
SUPPORTED_PYTHONS = ((3, 11), (3, 12), (3, 13))


def python_version_error() -> str | None:
    """Why this interpreter cannot run the project (None: it can)."""
    if sys.version_info[:2] in SUPPORTED_PYTHONS:
        return None
    supported = ", ".join(".".join(map(str, v)) for v in SUPPORTED_PYTHONS)
    return (
        f"condmon needs Python {supported} (environment.txt is pinned for them); this is Python "
        f"{platform.python_version()} at {sys.executable}. Make the virtual environment with one "
        f"of them (README.md, Set-up)."
    )
