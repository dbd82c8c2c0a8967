"""Paths shared by the studio tests (imported by name: pytest puts this folder on sys.path)."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT / "tests" / "bvh_corpus"
