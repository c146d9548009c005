"""The recordings benchmark runs as docs/recordings.md shows it: each of the page's commands, on
small sizes (the page's runs take minutes and gigabytes), checks what it promises (the same
predictions from every format, every lost frame counted) and prints its figures."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from docs_blocks import blocks_by, commands, run

pytest.importorskip("asammdf")

ROOT = Path(__file__).resolve().parents[1]
#: appended to each of the page's commands: argparse keeps an option's last value (the long recording in three
#: formats: the first part reads every bus-log format already)
SMALL = ["--frames", "300", "--long", "2000", "--long-formats", "log,csv,signal-mf4,csv-ahead", "--huge-dir"]


def test_the_recordings_benchmark_runs_as_the_page_shows_on_small_sizes(tmp_path: Path) -> None:
    [body] = blocks_by("docs/recordings.md",
                       "test_bench_recordings.py::test_the_recordings_benchmark_runs_as_the_page_shows_on_small_sizes")
    lines = commands(body)
    assert [line.split("#")[0].split()[:2] for line in lines] == [["python", "bench/bench_recordings.py"]] * 3
    for line in lines:
        argv = line.split("#")[0].split()[2:]
        if "--huge" in argv:
            argv += ["--huge", "3000"]
        out = run([sys.executable, str(ROOT / "bench" / "bench_recordings.py"), *argv, *SMALL, str(tmp_path)],
                  tmp_path, f"`{line}`", timeout=600)
        assert "300 Measurement frames" in out and "lost at random" in out, out[-2000:]
        if "--long 0" not in line:
            assert "2,000" in out or "2000" in out, out[-2000:]
            assert "log x4: 8,000 samples" in out, out[-2000:]  # the longer log, its peak beside the first's
            assert "signal MDF4" in out and "x the core" in out, out[-2000:]
            assert "predictions.csv the same streamed and held whole: True" in out, out[-2000:]
    assert not any(tmp_path.glob("*.csv")), "the huge recording was not deleted"
