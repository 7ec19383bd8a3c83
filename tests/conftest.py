"""Shared test constants (pytest puts this folder on sys.path: `from conftest import ROOT`)."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
