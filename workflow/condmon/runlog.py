"""Logging for Snakemake scripts: everything to the rule's log file, with timestamps."""

from __future__ import annotations

import logging
import signal
import sys


def setup_logging(snakemake) -> logging.Logger:
    """Send log records (and uncaught errors) of a Snakemake script to its `log:` file."""
    handlers = [logging.StreamHandler(sys.stderr)]
    if snakemake.log:
        handlers.append(logging.FileHandler(snakemake.log[0], mode="w"))
    logging.basicConfig(
        level=logging.INFO,
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
        handlers=handlers,
        force=True,
    )
    log = logging.getLogger(f"condmon.{snakemake.rule}")

    def excepthook(kind, value, tb):
        log.error("failed", exc_info=(kind, value, tb))

    sys.excepthook = excepthook

    def terminated(signum, frame):
        # SIGTERM (a scheduler or Snakemake stopping the job) as an exception, so that pending
        # `finally` blocks remove half-written temporary files
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, terminated)
    return log
