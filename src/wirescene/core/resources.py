"""Where the package's trained artefacts and bundled data live."""

from __future__ import annotations

from pathlib import Path

#: ``src/wirescene/data``: trained models (npz / JSON) and the bundled sample frames.
DATA_DIR = Path(__file__).resolve().parent.parent / "data"
