"""Readers and writers of run logs. :func:`open_run` picks the reader for a path."""

from __future__ import annotations

import os
from dataclasses import replace

from ads_rca.errors import InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB
from ads_rca.foundation.progress import Progress
from ads_rca.model import RunLog
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.bag.paths import is_bag
from ads_rca.sources.formats import (
    ATMACUP,
    AUTO,
    BAG,
    CARLA,
    DLP,
    FORMAT_NAMES,
    LOG,
    OPENLANE,
    SourceOptions,
    resolved_format,
)


def open_run(
    path: str | os.PathLike[str],
    remap: str | os.PathLike[str] | None = None,
    max_file_mb: float = DEFAULT_MAX_FILE_MB,
    progress: Progress | None = None,
    bag: BagOptions | None = None,
    workers: int = 1,
    source: SourceOptions | None = None,
) -> RunLog:
    """Load a run from any supported source (``source.source_format``, :mod:`.formats`;
    ``auto`` tells them apart by the path): an ADS running-log folder, a rosbag2 bag
    (directory, ``.mcap`` or ``.db3``) read through ``bag``'s profile (default: this
    project's topics; ``remap`` = topic remapping YAML for them, also ``bag.remap``), a CARLA
    experiment-client run folder, a DLP scene or an OpenLane-V2 segment (docs/formats.md;
    ``source`` holds their options: the derived collision, the DLP ego, a predictor's
    files to score).
    ``max_file_mb`` caps each file read whole (larger ones are reported and skipped);
    ``progress`` sees the files read, or the bag messages decoded; ``workers`` > 1 reads a
    long log folder in that many forked processes."""
    bag = bag or BagOptions()
    source = source or SourceOptions()
    source_format, derived_collision = source.source_format, source.derived_collision
    remap = remap if remap is not None else bag.remap
    if not os.path.lexists(path):
        raise InputError(f"{os.fspath(path)}: no such log folder or bag")
    fmt = resolved_format(path, source_format)
    kind = FORMAT_NAMES[fmt]
    if derived_collision and fmt not in (CARLA, DLP):
        raise InputError(
            f"{os.fspath(path)}: the derived collision check applies to CARLA runs and DLP "
            f"scenes, not to {kind}"
        )
    if source.ego_agent and fmt != DLP:
        raise InputError(f"{os.fspath(path)}: ego_agent applies to DLP scenes, not to {kind}")
    if source.predictions and fmt not in (CARLA, DLP, OPENLANE):
        raise InputError(
            f"{os.fspath(path)}: --predictions applies to CARLA runs, DLP scenes and OpenLane-V2 "
            f"segments (which hold no predictions), not to {kind}"
        )
    if fmt == OPENLANE:
        if remap is not None or not bag.contract:
            raise InputError("--profile and --remap apply to bags, not to an OpenLane-V2 segment")
        from ads_rca.sources.openlane.reader import read_openlane_segment

        return read_openlane_segment(path, max_file_mb, source)
    if source.submission and fmt != ATMACUP:
        raise InputError(
            f"{os.fspath(path)}: --submission applies to atmaCup tables, not to {kind}"
        )
    if fmt == ATMACUP:
        if remap is not None or not bag.contract:
            raise InputError("--profile and --remap apply to bags, not to an atmaCup table")
        from ads_rca.sources.atmacup.reader import read_atmacup_table

        return read_atmacup_table(path, max_file_mb, source)
    if fmt in (CARLA, DLP):
        log = _dataset_run(path, fmt, max_file_mb, source, remap, bag)
        if source.predictions:
            with_predictions(log, source.predictions, max_file_mb)
        return log
    if fmt == LOG and source_format != AUTO and is_bag(path):
        raise InputError(f"{os.fspath(path)}: --format {LOG}: this is a bag")
    if fmt == BAG and not is_bag(path):
        raise InputError(
            f"{os.fspath(path)}: --format {BAG}: not a bag (a .mcap or .db3 file, "
            "or a folder with metadata.yaml)"
        )
    if not bag.contract:
        if remap is not None:  # a remap given beside the options: the options' own check
            BagOptions(bag.profile, str(remap), bag.msg_path)
        if not is_bag(path):
            raise InputError(f"{os.fspath(path)}: profile {bag.profile!r} reads bags; not a bag")
        from ads_rca.sources.bag.profiles.recording import read_recording

        return read_recording(path, bag.profile, bag.msg_path, progress)
    if remap is not None or is_bag(path):
        from ads_rca.sources.bag.reader import read_bag

        return read_bag(path, remap=remap, progress=progress)
    from ads_rca.sources.log.reader import read_run_log

    return read_run_log(path, max_file_mb, progress, workers)


def _dataset_run(
    path: str | os.PathLike[str],
    fmt: str,
    max_file_mb: float,
    source: SourceOptions,
    remap: str | os.PathLike[str] | None,
    bag: BagOptions,
) -> RunLog:
    """A CARLA run or a DLP scene (no profile, no remapping: they are not bags)."""
    what = "a CARLA run folder" if fmt == CARLA else "a DLP scene"
    if remap is not None or not bag.contract:
        raise InputError(f"--profile and --remap apply to bags, not to {what}")
    if fmt == CARLA:
        from ads_rca.sources.carla.reader import read_carla_run

        return read_carla_run(path, max_file_mb, source.derived_collision)
    from ads_rca.sources.dlp.reader import read_dlp_scene

    return read_dlp_scene(path, max_file_mb, source)


def with_predictions(log: RunLog, directory: str, max_file_mb: float) -> None:
    """A predictor's prediction files put in ``log`` (which had none), its problems
    reported, and the capability record saying where they came from."""
    from ads_rca.model import INPUTS_KEY, InputStatus
    from ads_rca.sources.log.reader import read_predictions_folder

    found, problems = read_predictions_folder(directory, max_file_mb)
    log.predictions.update(found)
    log.problems.extend(problems)
    log.inputs["predictions"] = InputStatus(
        "real",
        os.fspath(directory),
        "a predictor's output given with --predictions: not judged by the verdict rules, "
        "scored against the realised future (ids are actor ids)",
    )
    raw = dict(log.metadata.raw)
    raw[INPUTS_KEY] = {name: s.to_dict() for name, s in log.inputs.items()}
    log.metadata = replace(log.metadata, raw=raw)
