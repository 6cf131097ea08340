"""A predictor's output for a run, written as prediction files to score (``--predictions``).

``write_predictions(log, folder, steps, bias)`` writes ``predictions-<ms>.json`` in the seed
format for every analysed frame: for each actor but the ego, the offsets (ego body frame at
that frame) of where the actor really is 1 … ``steps`` frames later, moved by ``bias`` metres
along the ego's x and y axes. A zero bias is a perfect predictor (ADE 0); a bias b of length
|b| gives ADE = FDE = |b| wherever the future is known, so the scores can be checked by hand.
"""

from __future__ import annotations

import json
from pathlib import Path

from ads_rca.foundation.geometry import world_to_ego
from ads_rca.model import RunLog


def write_predictions(
    log: RunLog,
    folder: str | Path,
    steps: int = 10,
    bias: tuple[float, float] = (0.0, 0.0),
    ego_id: str | None = None,
) -> Path:
    """Write the files (see the module docstring); returns the folder."""
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    for ts in log.frames:
        pose, actors = log.pose.get(ts), log.actors.get(ts)
        if pose is None or actors is None:
            continue
        document: dict[str, dict[str, dict[str, float]]] = {}
        for actor_id in actors.ids:
            if actor_id == ego_id:
                continue
            track: dict[str, dict[str, float]] = {}
            for k in range(steps):
                later = log.actors.get(ts + (k + 1) * log.frame_ms)
                row = later.index.get(actor_id) if later is not None else None
                if later is None or row is None:
                    break
                x, y = world_to_ego(later.location[row, 0:2], pose.xy, pose.yaw).tolist()
                track[str(k)] = {"x": x + bias[0], "y": y + bias[1], "z": 0.0}
            if track:
                document[actor_id] = track
        (root / f"predictions-{ts}.json").write_text(json.dumps(document))
    return root
