"""CSV files as measurement tools export them: ``;`` or tab separated, decimal commas, a unit row,
identified the same as the plain CSV of the same numbers; a file that is not CSV, a wrong separator,
a missing data or config file are errors that say what to do."""
from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn.cli import main
from pyrhonn.configfile import load_shipped, shipped_text
from pyrhonn.csvcodec import CellError, Layout, format_rows, parse_rows
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
    """A chunk of plain rows is parsed in C (an empty cell of a state that is not valid included); the
    same file with every cell quoted goes through the cell-by-cell reader: the same values, bit for bit."""
    cf = load_shipped("example1")
    import tempfile

    def write(path: Path, quoting: int) -> None:
        with path.open("w", newline="") as fh:
            w = csv.writer(fh, delimiter=sep, quoting=quoting)
            w.writerow(["t", "x1", "x2", "x3", "x4", "u", "x1_valid"])
            for k, row in enumerate(values):
                cells = [_CELL_STYLES[styles[j]](v) for j, v in enumerate(row)]
                if k == 0:
                    cells[0] = ""
                w.writerow([repr(0.5 * k)] + cells + ["0" if k == 0 else "1"])

    with tempfile.TemporaryDirectory() as tmp:
        write(Path(tmp) / "plain.csv", csv.QUOTE_MINIMAL)
        write(Path(tmp) / "quoted.csv", csv.QUOTE_ALL)
        a, b = read_data(Path(tmp) / "plain.csv", cf), read_data(Path(tmp) / "quoted.csv", cf)
    want = np.array(values)
    assert np.isnan(a.X[0, 0]) and not a.valid[0, 0] and a.valid[1:].all()
    np.testing.assert_array_equal(a.X[1:], want[1:, :4])
    np.testing.assert_array_equal(a.X[0, 1:], want[0, 1:4])
    np.testing.assert_array_equal(a.U[:, 0], want[:, 4])
    for field in ("X", "U", "valid", "t", "lines"):
        assert np.array_equal(getattr(a, field), getattr(b, field), equal_nan=True), field
    assert a.X.view(np.uint64)[1:].tolist() == b.X.view(np.uint64)[1:].tolist()  # -0.0 stays -0.0


# -- the C text codec (pyrhonn.csvcodec) --------------------------------------------------------------

def _bits(a: np.ndarray) -> list[int]:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64).ravel().tolist()


@settings(max_examples=150, deadline=None)
@given(values=st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64)
                       | st.floats(allow_nan=False, allow_infinity=False, width=32), min_size=1, max_size=40))
def test_every_finite_double_is_written_as_its_repr_and_reads_back_bit_for_bit(values: list[float]) -> None:
    """float64 and float32 values (as the float32 core's predictions are written, widened): the text of
    each is repr's, the shortest that reads back, and it reads back as the same bits."""
    x = np.array(values, dtype=np.float64)[:, None]
    text = format_rows(x)
    assert text.decode().split("\n")[:-1] == [repr(v) for v in x[:, 0].tolist()]
    numbers, _ = parse_rows(text, Layout(("v",), (0,)))
    assert _bits(numbers) == _bits(x)


def test_random_doubles_of_every_exponent_are_written_as_their_repr() -> None:
    """200,000 random bit patterns (every exponent, subnormals) and the powers of 2 and 10: repr's text,
    read back bit for bit."""
    rng = np.random.default_rng(11)
    x = rng.integers(0, 2**64 - 1, size=200_000, dtype=np.uint64, endpoint=True).view(np.float64)
    x = np.concatenate([x[np.isfinite(x)], 2.0 ** np.arange(-1074, 1024), 10.0 ** np.arange(-323, 308), [-0.0, 0.0]])
    text = format_rows(x.reshape(-1, 2) if x.size % 2 == 0 else x[:, None], sep=";")
    assert text.decode().replace("\n", ";").split(";")[:-1] == [repr(v) for v in x.tolist()]
    numbers, _ = parse_rows(text, Layout(("a", "b"), (0, 1)) if x.size % 2 == 0 else Layout(("a",), (0,)), sep=";")
    assert _bits(numbers) == _bits(x)


_DECIMAL = re.compile(r"[ ]*[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?[ ]*\Z")


@settings(max_examples=300, deadline=None)
@given(sign=st.sampled_from(["", "-", "+"]), whole=st.text("0123456789", max_size=25),
       point=st.booleans(), fraction=st.text("0123456789", max_size=25),
       exponent=st.none() | st.integers(-400, 400), spaces=st.booleans())
def test_a_decimal_number_is_read_as_float_reads_it(sign: str, whole: str, point: bool, fraction: str,
                                                     exponent: int | None, spaces: bool) -> None:
    """Any digits (more than 17, ties, subnormals, beyond the range): the same float64 as ``float``; a
    value beyond the float64 range is refused with its line and column."""
    cell = sign + whole + ("." + fraction if point else "") + ("" if exponent is None else f"e{exponent}")
    cell = f"  {cell} " if spaces else cell
    layout = Layout(("t", "x"), (1,))
    if not cell.strip():
        assert np.isnan(parse_rows(f"1,{cell}".encode(), layout)[0][0, 0])  # an empty cell: a missing value
        return
    if not _DECIMAL.match(cell):
        with pytest.raises(CellError) as refused:
            parse_rows(f"1,{cell}\n".encode(), layout)
        assert (refused.value.row, refused.value.column) == (1, "x")
        return
    want = float(cell)
    if not np.isfinite(want):
        with pytest.raises(CellError, match="line 1, column 'x'"):
            parse_rows(f"1,{cell}\n".encode(), layout)
        return
    numbers, _ = parse_rows(f"1,{cell}\n".encode(), layout)
    assert _bits(numbers) == _bits(np.array([want]))


@pytest.mark.parametrize("cell", [
    "9007199254740993", "9007199254740995", "1.00000000000000011102230246251565404236316680908203125",
    "1.00000000000000011102230246251565404236316680908203124", "2.4703282292062327e-324", "2.4703282292062328e-324",
    "4.9406564584124654e-324", "2.2250738585072011e-308", "2.2250738585072014e-308", "1.7976931348623157e308",
    "1.7976931348623158e308", "8.98846567431158e307", "1e23", "1e-400", "-0", "0e999", "123456789012345678901234e-30",
    "0.000000000000000000000000000000000000000000001e45", "5e-324", "7.2057594037927933e16",
])
def test_hard_decimals_are_rounded_as_float_rounds_them(cell: str) -> None:
    """Ties to even, the subnormal boundary, the largest double, more digits than the fast conversion takes."""
    numbers, _ = parse_rows(f"{cell}\n".encode(), Layout(("x",), (0,)))
    assert _bits(numbers) == _bits(np.array([float(cell)]))


def _reference(text: bytes, layout: Layout) -> tuple[list[list[float]], list[list[int]]] | tuple[int, str | None]:
    """What parse_rows reads from ``text``, cell by cell in Python: the values, or the refused line and field."""
    rows, flags = [], []
    lines = text.split(b"\n")
    ended = [True] * (len(lines) - 1) + [False]  # by a line end (\n or \r\n)
    if lines[-1] == b"":
        lines.pop()
    for i, (line, end) in enumerate(zip(lines, ended), 1):
        line = line[:-1] if end and line.endswith(b"\r") else line
        cells = line.split(b",")
        if not line.strip(b" \t") or b"\r" in line or len(cells) != len(layout.names):
            return i, None
        row = []
        for f in layout.numbers:
            cell = cells[f].decode("latin-1")
            if not cell.strip(" \t"):
                row.append(float("nan"))
                continue
            if not _DECIMAL.match(cell.replace("\t", " ")) or not np.isfinite(float(cell)):
                return i, layout.names[f]
            row.append(float(cell))
        rows.append(row)
        flags.append([int(cells[f]) if cells[f] in (b"0", b"1") else 2 for f in layout.flags])
    return rows, flags


@settings(max_examples=300, deadline=None)
@given(text=st.binary(max_size=200) | st.lists(st.sampled_from(
    [b"1", b"-2.5", b"1e5", b"", b" ", b"0", b"nan", b"x", b",", b"\n", b".", b"e", b"-", b"1e400", b"\t", b"\r",
     b"\r\n",
     b"\x00", b"\xff", b"9" * 22, b"5e-324"]), max_size=40).map(b"".join))
def test_any_bytes_are_parsed_as_the_cell_by_cell_reading_or_refused_at_the_same_cell(text: bytes) -> None:
    """Random bytes never crash the C parser: it returns what a cell-by-cell reading in Python returns
    (values bit for bit, flags), or refuses the same line and column."""
    layout = Layout(("a", "f", "b"), (0, 2), (1,))
    want = _reference(text, layout)
    try:
        numbers, flags = parse_rows(text, layout)
    except CellError as exc:
        assert (exc.row, exc.column) == want
        assert str(exc).startswith(f"line {exc.row}")
        return
    values, want_flags = want
    assert _bits(numbers) == _bits(np.array(values, dtype=np.float64).reshape(-1, 2))
    assert flags.tolist() == want_flags


@pytest.mark.parametrize("text, row, column", [
    (b"1,2\n3,nan\n", 2, "b"), (b"1,2\n3,inf\n", 2, "b"), (b"1,2\n1e999,2\n", 2, "a"), (b"1,2\n1,2,3\n", 2, None),
    (b"1,2\n\n1,2\n", 2, None), (b"1,2\n3\n", 2, None), (b"0x1,2\n", 1, "a"), (b"1,2.5.\n", 1, "b"),
    (b"1,--2\n", 1, "b"), (b"1,1e\n", 1, "b"), (b"1,1 2\n", 1, "b"), (b"1;5,2\n", 1, "a"),
    (b"1,2\r\n3,4\r5,6\r\n", 2, None), (b"x,2\r\n3,4\r", 1, "a"), (b"1,2\r\n3,4\r", 2, None),
])
def test_malformed_text_is_refused_naming_its_line_and_column(text: bytes, row: int, column: str | None) -> None:
    with pytest.raises(CellError) as refused:
        parse_rows(text, Layout(("a", "b"), (0, 1)))
    assert (refused.value.row, refused.value.column) == (row, column)
    assert str(refused.value).startswith(f"line {row}" + ("" if column is None else f", column {column!r}"))


def test_integer_columns_are_written_without_a_point_and_fractions_in_them_are_refused() -> None:
    values = np.array([[2.0, 0.5, 1.0], [3.0, -0.0, 0.0], [12345678901.0, np.nan, 1.0]])
    show = np.array([[True, True, True], [True, True, False], [True, True, True]])
    assert format_rows(values, show, integer=[True, False, True], sep="\t") == \
        b"2\t0.5\t1\n3\t-0.0\t\n12345678901\t\t1\n"
    with pytest.raises(ValueError, match="row 0, column 1: 0.5 is not a whole number"):
        format_rows(values, integer=[True, True, True])
    with pytest.raises(ValueError, match="row 2, column 0: 9.1e\\+16 is not a whole number"):
        format_rows(np.array([[1.0], [2.0], [9.1e16]]), integer=[True])


@pytest.mark.parametrize("values, show, message", [
    (np.zeros((2, 2), dtype=np.float32), None, "values: expected a 2-D float64 array"),
    (np.zeros(3), None, "values: expected a 2-D float64 array"),
    (np.zeros((2, 2)), np.ones((2, 3), dtype=bool), "show: expected a bool array of shape"),
    (np.zeros((2, 2)), np.ones((2, 2), dtype=np.uint8), "show: expected a bool array of shape"),
])
def test_format_rows_refuses_arrays_of_another_dtype_or_shape(values: np.ndarray, show: np.ndarray | None,
                                                             message: str) -> None:
    with pytest.raises(ValueError, match=message):
        format_rows(values, show)
