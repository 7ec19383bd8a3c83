"""Stage logic of the condition-monitoring pipeline, importable without Snakemake."""
import platform
import sys

# environment.txt and the rules' conda environments are resolved for this Python
REQUIRED_PYTHON = (3, 11)


def python_version_error() -> str | None:
    """Why this interpreter cannot run the project (None: it can)."""
    if sys.version_info[:2] == REQUIRED_PYTHON:
        return None
    required = ".".join(map(str, REQUIRED_PYTHON))
    return (f"condmon needs Python {required} (environment.txt is pinned for it); this is Python "
            f"{platform.python_version()} at {sys.executable}. Make the virtual environment with "
            f"python{required} (README.md, Set-up).")
