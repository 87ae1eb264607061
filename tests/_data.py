"""Location of the test shapes: ``../shared/data`` beside the repository, else the bundled copy."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_SHARED = ROOT.parent / "shared" / "data"
DATA = _SHARED if (_SHARED / "tosca").is_dir() else ROOT / "resources" / "data"
TOSCA = DATA / "tosca"
SUMNER = DATA / "sumner"
SKETCH2D = DATA / "sketch2d"
SILHOUETTES = DATA / "silhouettes"
assert TOSCA.is_dir(), f"test data not found in {DATA}"
