"""CSV files as measurement tools export them: ``;`` or tab separated, decimal commas, a unit row,
identified the same as the plain CSV of the same numbers; a file that is not CSV, a wrong separator,
a missing data or config file are errors that say what to do."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn.cli import main
from pyrhonn.configfile import load_shipped, shipped_text
from pyrhonn.datafile import read_data
from pyrhonn.plants import oscillator

NAMES = ["t", "x1", "x2", "x3", "x4", "u"]
UNITS = ["s", "m", "m/s", "[rad]", "(rad/s)", "V"]


@pytest.fixture(scope="module")
def rows() -> list[list[str]]:
    traj = oscillator.simulate(dt=0.2, horizon=12.0)
    out = []
    for k in range(traj.n_samples):
        out.append([repr(round(k * 0.2, 6))] + [repr(float(v)) for v in traj.X_meas[k]] + [repr(float(traj.U[k, 0]))])
    return out


def _write(path: Path, rows: list[list[str]], sep: str = ",", comma: bool = False, units: bool = False) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh, delimiter=sep, lineterminator="\r\n" if comma else "\n")
        w.writerow(NAMES)
        if units:
            w.writerow(UNITS)
        for r in rows:
            w.writerow([c.replace(".", ",") for c in r] if comma else r)
    return path


def _identify(data: Path, out: Path, *extra: str) -> list[str]:
    return ["identify", str(data), "--config", "example1", "--out", str(out), "--no-plots", *extra]


def _predictions(out: Path) -> list[dict[str, str]]:
    """The predictions without the line column (a unit row moves the data one line down)."""
    with (out / "predictions.csv").open(newline="") as fh:
        return [{k: v for k, v in row.items() if k != "line"} for row in csv.DictReader(fh)]


@pytest.mark.parametrize("sep, comma, units", [(";", True, True), ("\t", True, False), ("\t", False, True),
                                               (";", False, False)])
def test_a_tool_export_identifies_as_the_plain_csv(rows: list[list[str]], tmp_path: Path, sep: str, comma: bool,
                                                   units: bool) -> None:
    plain = _write(tmp_path / "plain.csv", rows)
    tool = _write(tmp_path / "tool.csv", rows, sep, comma, units)
    assert main(_identify(plain, tmp_path / "a")) == 0
    assert main(_identify(tool, tmp_path / "b")) == 0
    assert _predictions(tmp_path / "a") == _predictions(tmp_path / "b")
    a = json.loads((tmp_path / "a" / "metrics.json").read_text())
    b = json.loads((tmp_path / "b" / "metrics.json").read_text())
    assert a["states"] == b["states"]
    if units:
        assert b["units"] == dict(zip(NAMES, ["s", "m", "m/s", "rad", "rad/s", "V"]))
    else:
        assert "units" not in b


def test_separator_and_decimal_given_by_option_override_detection(rows: list[list[str]], tmp_path: Path,
                                                                   cli_error) -> None:
    tool = _write(tmp_path / "tool.csv", rows, ";", True)
    err = cli_error(_identify(tool, tmp_path / "x", "--csv-sep", ","))
    assert "missing columns 'x1', 'x2', 'x3', 'x4', 'u'" in err
    assert "is the file separated by semicolons? (--csv-sep ;)" in err
    err = cli_error(_identify(tool, tmp_path / "x", "--decimal", "."))
    assert "has a decimal comma; the file is read with a decimal point (--decimal , to read decimal commas)" in err
    assert main(_identify(tool, tmp_path / "ok", "--csv-sep", ";", "--decimal", ",")) == 0
    cf = load_shipped("example1")
    data = read_data(tool, cf)
    np.testing.assert_array_equal(data.X[:, 0], [float(r[1]) for r in rows])


def test_a_decimal_point_in_a_decimal_comma_file_is_named(rows: list[list[str]], tmp_path: Path) -> None:
    tool = _write(tmp_path / "tool.csv", rows, ";", True)
    lines = tool.read_bytes().split(b"\r\n")
    lines[5] = lines[5].replace(b",", b".", 1)
    tool.write_bytes(b"\r\n".join(lines))
    with pytest.raises(ValueError, match=r"line 6, column 't': '0\.8' has a decimal point, but the file's numbers "
                                         "use a decimal comma"):
        read_data(tool, load_shipped("example1"))


def test_files_that_are_not_csv_are_named_with_what_reads_them(tmp_path: Path, cli_error) -> None:
    (tmp_path / "run.csv").write_bytes(b"LOGG" + bytes(140))
    assert "run.csv: not a CSV file: a BLF bus log (binary); read it with --can-log" in cli_error(
        _identify(tmp_path / "run.csv", tmp_path / "o"))
    (tmp_path / "dump.csv").write_text("(1700000000.000000) vcan0 100#0011223344556677\n")
    assert "not a CSV file: a candump log; read it with --can-log" in cli_error(
        _identify(tmp_path / "dump.csv", tmp_path / "o"))
    (tmp_path / "m.csv").write_bytes(b"MDF     4.10    " + bytes(48))
    assert "not a CSV file: an MDF measurement file" in cli_error(_identify(tmp_path / "m.csv", tmp_path / "o"))


def test_a_missing_data_or_config_file_names_the_closest_file(rows: list[list[str]], tmp_path: Path,
                                                              cli_error) -> None:
    _write(tmp_path / "run_01.csv", rows)
    err = cli_error(_identify(tmp_path / "run_1.csv", tmp_path / "o"))
    assert "run_1.csv: No such file or directory; did you mean" in err and "run_01.csv" in err
    assert "Errno" not in err
    (tmp_path / "plant.toml").write_text(shipped_text("example1"))
    err = cli_error(["identify", str(tmp_path / "run_01.csv"), "--config", str(tmp_path / "plnat.toml")])
    assert "plnat.toml: No such file or directory; did you mean" in err and "plant.toml" in err
    err = cli_error(["identify", str(tmp_path / "none" / "run.csv"), "--config", "example1"])
    assert "does not exist either" in err


_CELL_STYLES = (repr, lambda v: f"{v:.17e}", lambda v: f"  {v!r} ", lambda v: f"{v:+.17g}")


@settings(max_examples=40, deadline=None)
@given(values=st.lists(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64), min_size=5, max_size=5),
                       min_size=2, max_size=30),
       styles=st.lists(st.integers(0, len(_CELL_STYLES) - 1), min_size=5, max_size=5),
       sep=st.sampled_from([",", ";", "\t"]))
def test_plain_rows_read_in_one_pass_equal_the_same_cells_read_one_by_one(values: list[list[float]], styles: list[int],
                                                                         sep: str) -> None:
    """A chunk of plain rows is read column by column; one empty cell sends its chunk through the
    cell-by-cell reader: every other value is the same, bit for bit."""
    cf = load_shipped("example1")
    import tempfile

    def write(path: Path, first_empty: bool) -> None:
        with path.open("w", newline="") as fh:
            w = csv.writer(fh, delimiter=sep)
            w.writerow(["t", "x1", "x2", "x3", "x4", "u", "x1_valid"])
            for k, row in enumerate(values):
                cells = [_CELL_STYLES[styles[j]](v) for j, v in enumerate(row)]
                if first_empty and k == 0:
                    cells[0] = ""
                w.writerow([repr(0.5 * k)] + cells + ["0" if first_empty and k == 0 else "1"])

    with tempfile.TemporaryDirectory() as tmp:
        write(Path(tmp) / "plain.csv", False)
        write(Path(tmp) / "mixed.csv", True)
        a, b = read_data(Path(tmp) / "plain.csv", cf), read_data(Path(tmp) / "mixed.csv", cf)
    want = np.array(values)
    np.testing.assert_array_equal(a.X, want[:, :4])
    np.testing.assert_array_equal(a.U[:, 0], want[:, 4])
    np.testing.assert_array_equal(b.X[1:], a.X[1:])
    np.testing.assert_array_equal(b.X[0, 1:], a.X[0, 1:])
    np.testing.assert_array_equal(b.U, a.U)
    assert not b.valid[0, 0] and b.valid[1:].all() and a.valid.all()
    np.testing.assert_array_equal(a.lines, b.lines)
