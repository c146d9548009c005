"""A trained identifier exported as a C header starts firmware from the
Python weights: compiled with the core, it reproduces Python's predictions
bit for bit."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import CovarianceForm, Identifier, IdentifierConfig, terms
from pyrhonn.export import export_header, header_text

from strategies import trajectory

ROOT = Path(__file__).resolve().parent.parent
CC = shutil.which("cc") or shutil.which("gcc")
pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler on PATH")


def vector_header(X: np.ndarray, U: np.ndarray, valid: np.ndarray, dtype: str) -> str:
    def arr(a: np.ndarray) -> str:
        return ", ".join(float(v).hex() + ("f" if dtype == "float32" else "") for v in a.ravel())
    Xz = np.where(valid, X, 0.0)  # dropped samples carry a placeholder the core ignores
    return "\n".join([
        f"#define VEC_T {X.shape[0]}", f"#define VEC_N {X.shape[1]}", f"#define VEC_M {U.shape[1]}",
        f"static const rhonn_real vec_x[] = {{{arr(Xz)}}};",
        f"static const rhonn_real vec_u[] = {{{arr(U) if U.size else '0'}}};",
        f"static const uint8_t vec_valid[] = {{{', '.join(str(int(v)) for v in valid.ravel())}}};", ""])


def build_and_run(tmp: Path, ident: Identifier, X, U, valid) -> np.ndarray:
    export_header(ident, tmp / "exported.h", name="EXPORTED")
    (tmp / "vector.h").write_text(vector_header(X, U, valid, ident.config.dtype))
    exe = tmp / "driver"
    flags = ["-DRHONN_SINGLE"] if ident.config.dtype == "float32" else []
    subprocess.run([CC, "-std=c99", "-O2", "-ffp-contract=off", "-Wall", "-Werror", *flags,
                    f"-I{ROOT / 'csrc' / 'include'}", f"-I{tmp}", str(ROOT / "tests" / "c" / "export_driver.c"),
                    str(ROOT / "csrc" / "src" / "rhonn.c"), "-o", str(exe)], check=True, capture_output=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    return np.array([[float.fromhex(v) for v in line.split()] for line in out.splitlines()])


@pytest.mark.parametrize("protection", [{}, dict(covariance=CovarianceForm.UD, forgetting=0.995,
                                                  p_trace_max=4000.0, reset_after=2)])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_exported_header_reproduces_python_predictions_bit_for_bit(tmp_path: Path, dtype: str,
                                                                   protection: dict) -> None:
    cfg = IdentifierConfig.uniform(
        terms.first_order(3, 2) + terms.pairwise_products(3, squares=True) + terms.delayed_taps(2, [3]) + terms.bias(),
        n_states=3, n_inputs=2, dtype=dtype, p0=100.0, q=1e-3, r=0.2, beta=0.9, **protection)
    X, U, valid = trajectory(11, 700, 3, 2, 0.05, dtype)
    trained = Identifier(cfg)
    trained.run(X[:400], U[:400], valid[:400])
    # Python side: a fresh identifier from the trained weights and covariances
    python = Identifier(trained.as_config()).run(X[400:], U[400:], valid[400:])
    firmware = build_and_run(tmp_path, trained, X[400:], U[400:], valid[400:])
    assert firmware.shape == python.shape
    np.testing.assert_array_equal(firmware.astype(python.dtype), python)
    # and it really starts from the trained weights, not from w0 = 0
    untrained = Identifier(cfg).run(X[400:], U[400:], valid[400:])
    assert not np.array_equal(untrained, python)
    if protection:  # the header carries the covariance form and the windup options
        text = header_text(trained, "EXPORTED")
        for field in (".covariance = RHONN_COV_UD", ".forgetting = ", ".p_trace_max = ", ".reset_after = 2"):
            assert text.count(field) == 3


def test_header_refuses_wrong_precision_and_small_capacity(tmp_path: Path) -> None:
    cfg = IdentifierConfig.uniform(terms.first_order(2), n_states=2, n_inputs=0, dtype="float32")
    export_header(cfg, tmp_path / "exported.h", name="EXPORTED")
    src = tmp_path / "use.c"
    src.write_text('#include "exported.h"\nint main(void) { return EXPORTED.n_states == 2 ? 0 : 1; }\n')
    base = [CC, "-std=c99", "-fsyntax-only", f"-I{ROOT / 'csrc' / 'include'}", f"-I{tmp_path}", str(src)]
    ok = subprocess.run(base + ["-DRHONN_SINGLE"], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    wrong = subprocess.run(base, capture_output=True, text=True)
    assert wrong.returncode != 0 and "exported as float32" in wrong.stderr
    small = subprocess.run(base + ["-DRHONN_SINGLE", "-DRHONN_MAX_STATES=1"], capture_output=True, text=True)
    assert small.returncode != 0 and "capacities are too small" in small.stderr


@pytest.mark.parametrize("name, message", [("int", "is a C keyword"), ("_Bool", "is a C keyword"),
                                           ("rhonn_init", "rhonn_ namespace"), ("RHONN_OK", "rhonn_ namespace"),
                                           ("__x", "reserved to the C implementation"),
                                           ("_Weights", "reserved to the C implementation"),
                                           ("abc\n", "expected a C identifier")])
def test_export_rejects_a_name_the_compiler_or_the_core_would_clash_with(name: str, message: str) -> None:
    cfg = IdentifierConfig.uniform(terms.first_order(2), n_states=2, n_inputs=0)
    with pytest.raises(ValueError, match=f"^name: .*{message}"):
        header_text(cfg, name)
    header_text(cfg, "rhonn_exported")  # the default name stays valid


@pytest.mark.parametrize("name", ["", "1abc", "a-b", "x y", None])
def test_export_rejects_a_name_that_is_not_a_c_identifier(name) -> None:
    cfg = IdentifierConfig.uniform(terms.first_order(1), n_states=1, n_inputs=0)
    with pytest.raises(ValueError, match="^name"):
        header_text(cfg, name)
