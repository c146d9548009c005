"""The exported header names each state and input in order, with its unit and bus signal, and the DBC
it goes with: comments for a reader, index and initialiser macros that C code compiles against."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from pyrhonn.cli import main
from pyrhonn.configfile import load_shipped, shipped_text
from pyrhonn.export import Signals, header_text

ROOT = Path(__file__).resolve().parent.parent
STATES = ("q_m", "v", "lambda_a", "lambda_b", "i_a", "i_b")
SIGNALS = ("Qm", "V", "LambdaA", "LambdaB", "Ia", "Ib", "Ua", "Ub")
BUS = "\n[bus]\nclock = \"Measurement\"\n\n[bus.signals]\n" + "".join(
    f"{n} = \"Measurement.{s}\"\n" for n, s in zip(STATES + ("u_a", "u_b"), SIGNALS))


def test_the_header_lists_states_and_inputs_with_units_signals_and_the_dbc(tmp_path: Path) -> None:
    (tmp_path / "lim.toml").write_text(shipped_text("firmware-lim") + BUS)
    assert main(["export", "--config", str(tmp_path / "lim.toml"), "--out", str(tmp_path / "lim_id.h"),
                 "--bus-dbc", str(ROOT / "firmware_sim" / "rhonn_id.dbc"), "--units", "u_b=V (beta)"]) == 0
    text = (tmp_path / "lim_id.h").read_text()
    assert " * Bus signals as in the DBC rhonn_id.dbc." in text
    assert " *   0: q_m [m]  Measurement.Qm" in text and " *   1: v [m/s]  Measurement.V" in text
    assert " *   1: u_b [V (beta)]  Measurement.Ub" in text
    assert "#define LIM_ID_N_STATES 6" in text and "#define LIM_ID_N_INPUTS 2" in text
    assert "#define LIM_ID_STATE_LAMBDA_B 3 /* lambda_b [Wb] */" in text
    assert "#define LIM_ID_INPUT_U_A 0" in text
    assert '#define LIM_ID_STATE_NAMES { "q_m", "v", "lambda_a", "lambda_b", "i_a", "i_b" }' in text
    assert '#define LIM_ID_INPUT_UNITS { "V", "V (beta)" }' in text


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_the_name_macros_compile_and_give_the_names_in_order(tmp_path: Path) -> None:
    cfg = load_shipped("example1").config
    sig = Signals(states=["x1", "x-2", "x3", "\u03b8"], inputs=["u"], units={"x1": "m", "\u03b8": "\u00b0"})
    (tmp_path / "ex.h").write_text(header_text(cfg, "ex", sig))
    (tmp_path / "main.c").write_text(
        '#include <stdio.h>\n#include "ex.h"\n'
        "int main(void) {\n"
        "    static const char *const names[EX_N_STATES] = EX_STATE_NAMES;\n"
        "    static const char *const units[EX_N_STATES] = EX_STATE_UNITS;\n"
        "    static const char *const inputs[EX_N_INPUTS] = EX_INPUT_NAMES;\n"
        "    int i;\n"
        "    for (i = 0; i < EX_N_STATES; ++i) printf(\"%s|%s\\n\", names[i], units[i]);\n"
        "    printf(\"%s %d %d %d\\n\", inputs[EX_INPUT_U], EX_STATE_X_2, EX_STATE_X1, (int)ex.n_states);\n"
        "    return 0;\n}\n")
    exe = tmp_path / "main"
    subprocess.run(["cc", "-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-I", str(ROOT / "csrc" / "include"),
                    "-I", str(tmp_path), str(tmp_path / "main.c"), "-o", str(exe)], check=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True).stdout.decode("utf-8")
    assert out.splitlines() == ["x1|m", "x-2|", "x3|", "\u03b8|\u00b0", "u 1 0 4"]


def test_names_that_do_not_fit_the_identifier_are_refused_naming_them() -> None:
    cfg = load_shipped("example1").config
    with pytest.raises(ValueError, match="signals: 2 state and 1 input names for an identifier of 4 states"):
        header_text(cfg, "ex", Signals(states=["a", "b"], inputs=["u"]))
    with pytest.raises(ValueError, match="the same macro NAME_STATE_X_1: x.1, x-1"):
        header_text(cfg, "ex", Signals(states=["x.1", "x-1", "c", "d"], inputs=["u"]))
    with pytest.raises(ValueError, match="signals.units: 'y' is not a state or input"):
        header_text(cfg, "ex", Signals(states=["a", "b", "c", "d"], inputs=["u"], units={"y": "m"}))


def test_export_refuses_a_unit_for_an_unknown_name_and_a_dbc_without_a_bus_table(tmp_path: Path, cli_error) -> None:
    err = cli_error(["export", "--config", "example1", "--out", str(tmp_path / "e.h"), "--units", "x9=m"])
    assert "--units: 'x9' is not a state or input of example1" in err
    err = cli_error(["export", "--config", "example1", "--out", str(tmp_path / "e.h"), "--bus-dbc",
                     str(ROOT / "firmware_sim" / "rhonn_id.dbc")])
    assert "has no [bus.signals] table" in err and not (tmp_path / "e.h").exists()
