"""A signal MDF4 (named channels on different time bases, as a measurement tool writes it) identifies
as the CSV of the same channels resampled by hand the stated way: zero-order hold of the latest
sample, a state valid only where its channel has a new sample in the period before; units come from
the channels; an unknown channel or an unfinalised file is named."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

asammdf = pytest.importorskip("asammdf")

from pyrhonn.cli import main  # noqa: E402

T = 0.01
# channel: (first time stamp, interval, unit); x3 is slower than the period, x4 offset by 3 ms, u faster
BASES = {"x1": (0.0, 0.01, "m"), "x2": (0.0, 0.01, "m/s"), "pos3": (0.0, 0.02, "rad"), "x4": (0.003, 0.01, ""),
         "u": (0.0, 0.005, "V")}
END = 3.0


def _value(name: str, t: np.ndarray) -> np.ndarray:
    w = {"x1": 1.0, "x2": 1.3, "pos3": 0.7, "x4": 2.1, "u": 0.3}[name]
    return np.sin(w * t) + 0.1 * np.cos(3 * w * t)


def _times(name: str) -> np.ndarray:
    t0, dt, _ = BASES[name]
    return t0 + dt * np.arange(int(round((END - t0) / dt)) + 1)


@pytest.fixture(scope="module")
def mf4(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("mdf") / "run.mf4"
    mdf = asammdf.MDF(version="4.10")
    for name, (_, _, unit) in BASES.items():  # one channel group per time base
        t = _times(name)
        mdf.append([asammdf.Signal(_value(name, t), t, name=name, unit=unit)], comment=name)
    mdf.save(str(path), overwrite=True)
    mdf.close()
    return path


def _by_hand(path: Path) -> None:
    """The grid from 3 ms (the latest first sample) to the earliest last one, every 10 ms; each channel's
    latest sample at or before the grid time; a state valid when that sample is less than 10 ms old."""
    grid = 0.003 + T * np.arange(int((END - 0.003) / T + 1e-9) + 1)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "x1", "x2", "x3", "x4", "u", "x1_valid", "x2_valid", "x3_valid", "x4_valid"])
        for tk in grid:
            row, flags = [repr(float(tk))], []
            for name in ("x1", "x2", "pos3", "x4", "u"):
                t0, dt, _ = BASES[name]
                j = int(np.floor((tk - t0) / dt + 1e-9))
                ts = t0 + dt * j
                value = float(_value(name, np.array([ts]))[0])
                fresh = tk - ts < T - 1e-9
                if name == "u":
                    row.append(repr(value))
                else:
                    row.append(repr(value) if fresh else "")
                    flags.append("1" if fresh else "0")
            w.writerow(row + flags)


def _predictions(out: Path) -> list[dict[str, str]]:
    with (out / "predictions.csv").open(newline="") as fh:
        return [{k: v for k, v in row.items() if k.endswith(("_hat", "_err"))} for row in csv.DictReader(fh)]


def test_a_signal_mdf4_identifies_as_the_csv_resampled_by_hand(mf4: Path, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    _by_hand(tmp_path / "hand.csv")
    assert main(["identify", str(tmp_path / "hand.csv"), "--config", "example1", "--out", str(tmp_path / "csv"),
                 "--no-plots"]) == 0
    assert main(["identify", str(mf4), "--config", "example1", "--channel", "x3=pos3", "--sample-period", "0.01",
                 "--out", str(tmp_path / "mdf"), "--no-plots"]) == 0
    printed = capsys.readouterr().out
    assert "resampled by zero-order hold of the latest sample" in printed
    assert _predictions(tmp_path / "mdf") == _predictions(tmp_path / "csv")
    report = json.loads((tmp_path / "mdf" / "metrics.json").read_text())
    assert report["units"] == {"x1": "m", "x2": "m/s", "x3": "rad", "u": "V"}
    ch = report["mdf"]["channels"]
    assert ch["x3"]["channel"] == "pos3" and ch["x3"]["not_valid"] == report["samples"] // 2
    assert ch["x1"]["not_valid"] == 0 and ch["u"]["interval"] == pytest.approx(0.005)
    assert report["mdf"]["sample_period_from"] == "--sample-period"


def test_an_unknown_channel_and_an_unfinalised_file_are_named(mf4: Path, tmp_path: Path, cli_error) -> None:
    err = cli_error(["identify", str(mf4), "--config", "example1", "--out", str(tmp_path / "o")])
    assert "no channel 'x3' for 'x3'" in err and "(it has: " in err and "pos3" in err
    err = cli_error(["identify", str(mf4), "--config", "example1", "--channel", "x3=pos", "--out", str(tmp_path / "o")])
    assert "no channel 'pos' for 'x3'; did you mean 'pos3'?" in err
    raw = bytearray(mf4.read_bytes())
    raw[:8] = b"UnFinMF "
    (tmp_path / "open.mf4").write_bytes(bytes(raw))
    args = ["identify", str(tmp_path / "open.mf4"), "--config", "example1", "--channel", "x3=pos3", "--no-plots"]
    err = cli_error(args + ["--out", str(tmp_path / "o")])
    assert "truncated: its identification block says 'UnFinMF'" in err and "--partial-log" in err
    assert main(args + ["--out", str(tmp_path / "p"), "--partial-log"]) == 0
    assert json.loads((tmp_path / "p" / "metrics.json").read_text())["mdf"]["complete"] is False


def test_a_signal_mdf4_cut_short_is_refused_before_it_is_read(mf4: Path, tmp_path: Path, cli_error) -> None:
    """asammdf writes the channel blocks after the data: a cut halfway leaves nothing, --partial-log or not."""
    raw = mf4.read_bytes()
    (tmp_path / "cut.mf4").write_bytes(raw[:len(raw) // 2])
    for partial in ([], ["--partial-log"]):
        err = cli_error(["identify", str(tmp_path / "cut.mf4"), "--config", "example1", "--channel", "x3=pos3",
                         "--out", str(tmp_path / "o"), *partial])
        assert "cut.mf4: truncated: cut short: its blocks reach byte" in err and "bytes missing" in err
        assert "nothing in it can be read, not even with --partial-log" in err


def test_without_asammdf_an_mdf4_is_refused_saying_what_to_install(mf4: Path, tmp_path: Path, cli_error,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util

    from pyrhonn import mdfsignals

    real = importlib.util.find_spec
    monkeypatch.setattr(mdfsignals.importlib.util, "find_spec", lambda name, *a: None if name == "asammdf" else
                        real(name, *a))
    err = cli_error(["identify", str(mf4), "--config", "example1", "--out", str(tmp_path / "o")])
    assert f"{mf4}: reading MDF4 needs asammdf: pip install 'pyrhonn[mdf]'" in err
    dbc = Path(__file__).resolve().parent.parent / "firmware_sim" / "rhonn_id.dbc"
    err = cli_error(["identify", "--can-log", str(mf4), "--dbc", str(dbc), "--config", "example1", "--out",
                     str(tmp_path / "o")])
    assert f"--can-log {mf4}: reading MDF4 needs asammdf: pip install 'pyrhonn[mdf]'" in err
