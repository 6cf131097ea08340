"""The options a batch's rows were made with, recorded beside them (``OUT/options.json``).

A row means what its verdict means under the options that made it: the semantics, every
threshold (``--config`` and ``-p`` resolved), the reader's settings (``--max-file-mb``,
``--format``, ``--ego-agent``, ``--predictions``, ``--submission``, ``--derived-collision``)
and the bag's (``--profile``, ``--remap``, ``--msg-path``). ``--resume`` with other options
silently mixed rows of both kinds in one table (issue 43), so the first batch in a folder
records them and ``--resume`` refuses, in one line naming each option that differs with its
recorded and its new value, when they are not the same. A file option (a profile YAML, a
remapping, a submission) is recorded by its absolute path and the SHA-256 of its content:
the same name with other content is another option. How the work runs (``--workers``,
``--scheduler``, ``--timeout``, ``--retries``) changes no verdict and is not recorded.

A folder from before the record (rows, no ``options.json``): its rows still say their
semantics and, for bags, their profile; a difference there is refused as any other. Nothing
else can be compared, so the batch goes on, says so in one line, and records the new
options: those older results are taken to be made with them (docs/batch.md).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

from ads_rca.batch.store import CSV_NAME, read_csv
from ads_rca.errors import InputError
from ads_rca.foundation.atomic_write import replace_bytes
from ads_rca.foundation.files import Unreadable, open_regular, read_regular
from ads_rca.foundation.text import printable
from ads_rca.params import Params
from ads_rca.sources.bag.options import BagOptions
from ads_rca.sources.formats import SourceOptions

OPTIONS_NAME = "options.json"
#: The record's format (a later version that records more says so here).
RECORD_VERSION = 1
#: A record larger than this is no record of ours.
MAX_RECORD_BYTES = 1 << 20
_Value = str | int | float | bool | list[str] | None


def options_record(
    params: Params, max_file_mb: float, source: SourceOptions, bag: BagOptions
) -> dict[str, _Value]:
    """The options that decide what a row says, by the name a user gives them."""
    record: dict[str, _Value] = {"--semantics": params.semantics}
    for name, value in asdict(params).items():
        if name != "semantics":
            record[f"-p {name}"] = value
    record["--max-file-mb"] = max_file_mb
    record["--format"] = source.source_format
    record["--derived-collision"] = source.derived_collision
    record["--ego-agent"] = source.ego_agent
    record["--predictions"] = _absolute(source.predictions)
    record["--submission"] = _file(source.submission)
    record["--profile"] = _file(bag.profile) if os.path.isfile(bag.profile) else bag.profile
    record["--remap"] = _file(bag.remap or "")
    record["--msg-path"] = [os.path.abspath(p) for p in bag.msg_path]
    return record


def check_resume(out: Path, record: Mapping[str, _Value]) -> str | None:
    """:class:`InputError` when ``out``'s results were made with other options than
    ``record``; a line to say when ``out`` has rows but no record (module docstring)."""
    stored = read_record(out)
    if stored is not None:
        differ = [
            f"{name} {_shown(stored.get(name))} (now {_shown(record.get(name))})"
            for name in [*record, *(n for n in stored if n not in record)]
            if stored.get(name, _MISSING) != record.get(name, _MISSING)
        ]
        if differ:
            raise InputError(
                f"--resume {printable(out)}: its results were made with other options: "
                f"{'; '.join(differ)}; give the same options, or a new --out"
            )
        return None
    csv_path = out / CSV_NAME
    listed = read_csv(csv_path) if csv_path.is_file() else []
    if not listed:
        return None
    differ = [
        f"{name} {_shown(seen)} (now {_shown(record[name])})"
        for name, column in (("--semantics", "semantics"), ("--profile", "profile"))
        for seen in sorted({str(r[column]) for r in listed if r.get(column)})
        if seen != _row_value(record[name])
    ]
    if differ:
        raise InputError(
            f"--resume {printable(out)}: its rows were made with other options: "
            f"{'; '.join(differ)}; give the same options, or a new --out"
        )
    return (
        f"--resume: {printable(out)} has no {OPTIONS_NAME} (made before the options were "
        f"recorded): its {len(listed)} rows' semantics and profile match; its other options "
        "are taken to be these, and recorded"
    )


def read_record(out: Path) -> dict[str, Any] | None:
    """``out``'s recorded options, None when there is none; InputError when unreadable."""
    path = out / OPTIONS_NAME
    if not os.path.lexists(path):
        return None
    data = read_regular(path, MAX_RECORD_BYTES)
    why = data.issue if isinstance(data, Unreadable) else ""
    document: Any = None
    if isinstance(data, bytes):
        try:
            document = json.loads(data)
        except (UnicodeDecodeError, json.JSONDecodeError) as error:
            why = f"not JSON ({error})"
    if not why and not (
        isinstance(document, dict)
        and document.get("version") == RECORD_VERSION
        and isinstance(document.get("options"), dict)
    ):
        why = f"not a version {RECORD_VERSION} record of ads-rca batch's options"
    if why:
        raise InputError(f"--resume {printable(path)}: cannot read ({printable(why)})")
    options: dict[str, Any] = document["options"]
    return options


def write_record(out: Path, record: Mapping[str, _Value]) -> None:
    """``out/options.json`` replaced whole (an OSError for the caller's one line)."""
    document = {"version": RECORD_VERSION, "options": dict(record)}
    replace_bytes(out / OPTIONS_NAME, (json.dumps(document, indent=1) + "\n").encode("utf-8"))


_MISSING = object()


def _shown(value: object) -> str:
    if value is None:
        return "(absent)"
    if isinstance(value, list):
        return ",".join(map(str, value)) or "(none)"
    text = str(value) if value != "" else '""'
    return printable(text if len(text) <= 120 else text[:117] + "...")


def _row_value(value: _Value) -> str:
    """How a row's column shows the option (a profile file: its path)."""
    return str(value).split(" (sha256 ", 1)[0]


def _absolute(path: str) -> str:
    return os.path.abspath(path) if path else ""


def _file(path: str) -> str:
    """A file option: its absolute path and the SHA-256 of its content ("" for none)."""
    if not path:
        return ""
    opened = open_regular(path)
    if isinstance(opened, Unreadable):
        return f"{os.path.abspath(path)} (unreadable: {opened.issue})"
    digest = hashlib.sha256()
    with opened:
        while block := opened.read(1 << 20):
            digest.update(block)
    return f"{os.path.abspath(path)} (sha256 {digest.hexdigest()[:16]})"
