"""A real run whose verdict is inconclusive (docs/verdicts.md), for the batch, ``watch`` and
dashboard tests: the bundled crash without its detections (perception not judged) and
without a collision frame in its metadata (collision unknown)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cut_in_perception"


def unsure_copy(dest: Path) -> Path:
    """The copy at ``dest``: its verdict is "inconclusive: collision unknown (...);
    perception not judged (no detections_2d)", with no root cause."""
    run = Path(shutil.copytree(EXAMPLE, dest))
    shutil.rmtree(run / "bboxes")
    metadata = json.loads((run / "metadata.json").read_text())
    del metadata["collision_frame"], metadata["synthesis"]["collision_frame"]
    (run / "metadata.json").write_text(json.dumps(metadata))
    return run
