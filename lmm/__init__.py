"""lmm: the Motion Matching / Learned Motion Matching engine (numpy at run time, no GUI, no GL)."""
from pathlib import Path

__version__ = "0.1.0"

DATA_DIR = Path(__file__).resolve().parent / "data"
DEFAULT_MANIFEST = DATA_DIR / "default_manifest.json"
