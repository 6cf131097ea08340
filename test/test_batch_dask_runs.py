"""``ads-rca batch`` on a real Dask cluster on loopback.

No mocks: the command runs as a process with its own ``LocalCluster`` (or, for the killed
worker, our own cluster through ``--scheduler``). Checked: 200 synthesised runs of mixed
faults give the same verdict JSON, byte for byte, as ``diagnose`` one by one, and rows that
say the same; a corrupt run and a run past ``--timeout`` are rows with their errors while
the rest complete; a worker SIGKILLed mid-batch still yields every row; Ctrl-C keeps every
finished row, exits 130 without a traceback, and ``--resume`` completes the batch without
redoing finished runs; bad inputs are one line each.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from commandline import start_cli

from ads_rca.batch.inputs import run_id
from ads_rca.batch.rows import COLUMNS
from ads_rca.batch.store import read_csv, read_parquet
from ads_rca.cli import main
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

REPO = Path(__file__).resolve().parents[1]
FRAMES = 120
#: Distinct synthesised logs; the 200 runs are these at 10 paths each (synthesis costs ~1 s
#: a log, diagnosis well under that: copies keep the test about the batch, not the synth).
DISTINCT = 20
#: (scenario, fault) pairs that crash, cycled over the seeds.
MIX = [
    (scenario, fault)
    for scenario in ("cut_in", "lead_braking", "pedestrian_crossing", "left_turn")
    for fault in ("none", "perception", "prediction", "planning", "controller")
]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return env


def batch(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", "batch", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=_env(),
        check=False,
    )


def start_batch(*args: str) -> subprocess.Popen[str]:
    return start_cli("batch", *args)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Callable[[int], list[Path]]:
    """The first ``n`` of 200 runs of mixed scenarios and faults (:data:`DISTINCT` logs)."""
    root = tmp_path_factory.mktemp("batch_runs")
    made: list[Path] = []

    def get(n: int) -> list[Path]:
        while len(made) < n:
            i = len(made)
            scenario, fault = MIX[i % len(MIX)]
            folder = root / f"run_{i:03d}_{scenario}_{fault}"
            if i < DISTINCT:
                made.append(write_run_log(synthesise(scenario, fault, 0, frames=FRAMES), folder))
            else:
                made.append(Path(shutil.copytree(made[i % DISTINCT], folder)))
        return made[:n]

    return get


def paths_file(folder: Path, paths: list[Path]) -> Path:
    listing = folder / "paths.txt"
    listing.write_text("# runs\n" + "".join(f"{p}\n" for p in paths))
    return listing


def diagnose_json(path: Path, out: Path) -> bytes:
    """``ads-rca diagnose PATH --json``'s bytes (in this process)."""
    assert main(["diagnose", str(path), "--json", str(out), "--workers", "1"]) == 0
    return out.read_bytes()


@pytest.mark.slow
def test_200_runs_match_diagnose_one_by_one(
    runs: Callable[[int], list[Path]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = runs(200)
    out = tmp_path / "out"
    started = time.monotonic()
    done = batch(str(paths_file(tmp_path, paths)), "--out", str(out), "--workers", "2")
    elapsed = time.monotonic() - started
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    rows = read_csv(out / "results.csv")
    assert len(rows) == 200
    assert _view(read_parquet(out / "results.parquet")) == _view(rows)
    by_path = {row["path"]: row for row in rows}
    causes: set[str] = set()
    expected: dict[int, bytes] = {}  # diagnose one by one: each distinct log's bytes
    for i, path in enumerate(paths):
        row = by_path[os.path.realpath(path)]
        assert row["error"] == "" and row["run_id"] == run_id(path)
        written = (out / "runs" / f"{row['run_id']}.json").read_bytes()
        if i < DISTINCT:
            expected[i] = diagnose_json(path, tmp_path / "one.json")
            assert written == expected[i]
        else:  # a copy: the same verdict, its own path as the source
            document = json.loads(expected[i % DISTINCT])
            document["source"] = json.loads(written)["source"]
            assert json.loads(written) == document
            assert document["source"] == os.path.realpath(path)
        document = json.loads(written)
        assert row["primary_root_cause"] == (document["primary_root_cause"] or "")
        assert row["collision_frame"] == document["collision_frame"]
        assert row["frames"] == len(document["frames"])
        assert row["scenario"] == path.name.split("_", 2)[2].rsplit("_", 1)[0]
        causes.add(row["primary_root_cause"])
    capsys.readouterr()
    assert {"perception", "prediction", "planning", "controller"} <= causes
    assert "by primary root cause:" in done.stdout and "by scenario family:" in done.stdout
    html = (out / "summary.html").read_text()
    assert html.count("data:image/png;base64,") >= 2 and "<script" not in html
    print(f"200 runs with 2 workers: {elapsed:.1f} s")


def _view(rows: list[dict[str, object]]) -> list[dict[str, object]]:
    """Rows comparable with ``==`` (a NaN is never equal to itself: None here)."""
    return [
        {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()}
        for row in rows
    ]


@pytest.mark.slow
def test_corrupt_and_hanging_runs_are_rows_and_the_rest_complete(
    runs: Callable[[int], list[Path]], tmp_path: Path
) -> None:
    good = runs(4)
    corrupt = tmp_path / "corrupt"
    write_run_log(synthesise("cut_in", "planning", 0, frames=FRAMES), corrupt)
    (corrupt / "metadata.json").write_text('{"collision_frame": 12, "trunc')
    shutil.rmtree(corrupt / "actors")  # no frame left to judge
    garbage = tmp_path / "garbage"
    garbage.mkdir()
    (garbage / "notes.bin").write_bytes(os.urandom(64))
    slow = tmp_path / "slow"
    write_run_log(synthesise("cruise", "none", 0, frames=3000, actors=30), slow)  # ~5 s alone
    # A folder name that is not UTF-8 and a label with a lone surrogate: valid runs whose
    # texts CSV, Parquet and HTML cannot hold as they are (the batch crashed on them).
    odd = Path(shutil.copytree(good[0], tmp_path / os.fsdecode(b"odd\xff")))
    labelled = Path(shutil.copytree(good[1], tmp_path / "labelled"))
    metadata = json.loads((labelled / "metadata.json").read_text())
    metadata["synthesis"]["scenario"] = "\ud800cut"
    (labelled / "metadata.json").write_text(json.dumps(metadata))
    out = tmp_path / "out"
    done = batch(
        *map(str, good), str(corrupt), str(garbage), str(slow), str(odd), str(labelled),
        "--out", str(out), "--workers", "2", "--timeout", "2",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    rows = {row["path"]: row for row in read_csv(out / "results.csv")}
    assert len(rows) == 9 and len(read_parquet(out / "results.parquet")) == 9
    escaped = os.path.realpath(odd).encode("utf-8", "surrogateescape").decode("utf-8", "replace")
    assert rows[str(tmp_path.resolve() / "odd\\udcff")]["error"] == "", escaped
    assert rows[os.path.realpath(labelled)]["scenario"] == "\\ud800cut"
    assert "\\ud800cut" in (out / "summary.html").read_text(encoding="utf-8")
    del rows[str(tmp_path.resolve() / "odd\\udcff")], rows[os.path.realpath(labelled)]
    assert "no frame to analyse" in rows[os.path.realpath(corrupt)]["error"]
    assert "not an ADS running log" in rows[os.path.realpath(garbage)]["error"]
    assert rows[os.path.realpath(slow)]["error"] == "timed out after 2 s"
    assert all(rows[os.path.realpath(p)]["error"] == "" for p in good)
    assert "failures (3):" in done.stdout


def _worker_pids(parent: int) -> list[int]:
    """The Dask worker processes a batch command started (its spawned children)."""
    import psutil

    return [
        child.pid
        for child in psutil.Process(parent).children()
        if "spawn_main" in " ".join(child.cmdline())
    ]


def _rows_written(out: Path) -> int:
    try:
        return max(0, (out / "results.csv").read_text().count("\n") - 1)
    except FileNotFoundError:
        return 0


def _wait_rows(out: Path, n: int, process: subprocess.Popen[str], limit: float = 120) -> None:
    deadline = time.monotonic() + limit
    while _rows_written(out) < n:
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)


@pytest.mark.slow
def test_a_worker_killed_mid_batch_still_yields_every_row(
    runs: Callable[[int], list[Path]], tmp_path: Path
) -> None:
    paths = runs(60)
    out = tmp_path / "out"
    process = start_batch(str(paths_file(tmp_path, paths)), "--out", str(out), "--workers", "2")
    try:
        _wait_rows(out, 5, process)
        workers = _worker_pids(process.pid)
        assert len(workers) == 2
        os.kill(workers[0], signal.SIGKILL)
        _stdout, stderr = process.communicate(timeout=300)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, stderr
    rows = read_csv(out / "results.csv")
    assert sorted(r["path"] for r in rows) == sorted(os.path.realpath(p) for p in paths)
    assert all(r["error"] == "" for r in rows), [r["error"] for r in rows if r["error"]]
    assert len({r["worker"] for r in rows}) >= 2


@pytest.mark.slow
def test_ctrl_c_keeps_finished_rows_and_resume_completes_without_redoing(
    runs: Callable[[int], list[Path]], tmp_path: Path
) -> None:
    paths = runs(60)
    listing = paths_file(tmp_path, paths)
    out = tmp_path / "out"
    process = start_batch(str(listing), "--out", str(out), "--workers", "1")
    try:
        _wait_rows(out, 10, process)
        workers = _worker_pids(process.pid)
        process.send_signal(signal.SIGINT)
        _stdout, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr and "--resume" in stderr
    first = read_csv(out / "results.csv")
    assert 10 <= len(first) < 60
    assert len(list((out / "runs").glob("*.json"))) >= len(first)
    assert len(read_parquet(out / "results.parquet")) == len(first)
    time.sleep(0.5)
    import psutil

    assert not [pid for pid in workers if psutil.pid_exists(pid)]  # the cluster is gone

    resumed = batch(str(listing), "--out", str(out), "--workers", "1", "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert f"--resume: {len(first)} of 60 runs already done" in resumed.stdout
    final = read_csv(out / "results.csv")
    assert len(final) == 60 and len({r["run_id"] for r in final}) == 60
    assert _view(final[: len(first)]) == _view(first)  # the finished runs were not redone
    again = batch(str(listing), "--out", str(out), "--resume")
    assert again.returncode == 0 and "60 of 60 runs already done" in again.stdout


def test_columns_are_fixed_and_documented() -> None:
    text = (REPO / "docs" / "batch.md").read_text()
    assert [c for c in COLUMNS if f"`{c}`" not in text] == []


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["/nonexistent/run"], "/nonexistent/run: no such log folder, bag or paths file"),
        (["/nonexistent/*/x"], "/nonexistent/*/x: the glob matches nothing"),
        (["{listing}"], "paths.txt:2: {missing}: no such log folder or bag"),
        (["{binary}"], "binary data, not a text file of paths"),
        (["{run}", "--out", "{full}"], "exists and is not empty (--resume continues"),
        (["{run}", "--workers", "0"], "--workers 0: expected 1 to 512"),
        (["{run}", "--timeout", "-1"], "--timeout -1: expected a positive number"),
        (["{run}", "--scheduler", "host:1"], "--scheduler host:1: expected an address like"),
        (["{run}", "--out", "/proc/batch"], "--out /proc/batch: cannot write"),
    ],
)
def test_bad_inputs_are_one_line(
    args: list[str],
    message: str,
    runs: Callable[[int], list[Path]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    run = runs(1)[0]
    listing = tmp_path / "paths.txt"
    listing.write_text(f"{run}\n{tmp_path / 'missing'}\n")
    binary = tmp_path / "bin.txt"
    binary.write_bytes(b"\x00\x01garbage")
    full = tmp_path / "full"
    full.mkdir()
    (full / "x").write_text("x")
    names = {"listing": listing, "binary": binary, "run": run, "full": full}
    names["missing"] = tmp_path / "missing"
    argv = [a.format(**names) for a in args]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "out")]
    assert main(["batch", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message.format(**names) in err, err
