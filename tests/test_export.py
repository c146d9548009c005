"""A trained identifier exported as C headers starts firmware from the
Python weights: compiled with the core, as C99 or as C++, it reproduces
Python's predictions bit for bit; the capacity header it comes with is the
smallest that holds it and states sizeof(rhonn_t) truly; a warm start
continues a running identifier bit for bit."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import CovarianceForm, Identifier, IdentifierConfig, terms
from pyrhonn.export import (LAYOUT_VERSION, capacity_path, capacity_text, export_header, header_text,
                            min_capacities)

from strategies import trajectory

ROOT = Path(__file__).resolve().parent.parent
INCLUDE = ROOT / "csrc" / "include"
CORE = [ROOT / "csrc" / "src" / "rhonn.c", ROOT / "csrc" / "src" / "rhonn_warm.c"]
DRIVER = ROOT / "tests" / "c" / "export_driver.c"
CC = shutil.which("cc") or shutil.which("gcc")
pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler on PATH")
# C++ compilers: CI (.ci/run) installs g++ and clang-14 and sets PYRHONN_REQUIRE_CXX=1
CXX = {name: shutil.which(cmd) for name, cmds in (("g++", ("g++",)), ("clang++", ("clang++", "clang++-14")))
       for cmd in cmds if shutil.which(cmd)}
STRICT = ["-Wall", "-Wextra", "-pedantic", "-Werror"]


def cxx(name: str) -> str:
    if name not in CXX:
        if os.environ.get("PYRHONN_REQUIRE_CXX") == "1":
            pytest.fail(f"PYRHONN_REQUIRE_CXX=1 but {name} is not on PATH")
        pytest.skip(f"{name} not on PATH")
    return CXX[name]


def vector_header(X: np.ndarray, U: np.ndarray, valid: np.ndarray, dtype: str) -> str:
    """The test vector, exact in C (hex) and in C++11 (shortest round-trip decimal)."""
    suffix = "f" if dtype == "float32" else ""

    def arr(a: np.ndarray, hexa: bool) -> str:
        vals = [float(v) for v in a.ravel()] or [0.0]
        if hexa:
            return ", ".join(v.hex() + suffix for v in vals)
        if dtype == "float32":
            return ", ".join(np.format_float_scientific(np.float32(v), unique=True) + suffix for v in vals)
        return ", ".join(repr(v) for v in vals)

    Xz = np.where(valid, X, 0.0)  # dropped samples carry a placeholder the core ignores
    lines = [f"#define VEC_T {X.shape[0]}", f"#define VEC_N {X.shape[1]}", f"#define VEC_M {U.shape[1]}",
             f"static const uint8_t vec_valid[] = {{{', '.join(str(int(v)) for v in valid.ravel())}}};",
             "#if !defined(__cplusplus) || __cplusplus >= 201703L"]
    for hexa in (True, False):
        lines += [f"static const rhonn_real vec_x[] = {{{arr(Xz, hexa)}}};",
                  f"static const rhonn_real vec_u[] = {{{arr(U, hexa)}}};"]
        lines.append("#else" if hexa else "#endif")
    return "\n".join(lines) + "\n"


def core_objects(tmp: Path, dtype: str, defines: list[str]) -> list[str]:
    """The core compiled as C99 (the firmware's way), once per test."""
    objs = []
    for src in CORE:
        obj = tmp / f"{src.stem}.o"
        subprocess.run([CC, "-std=c99", "-O2", "-ffp-contract=off", *STRICT, *defines, f"-I{INCLUDE}", f"-I{tmp}",
                        "-c", str(src), "-o", str(obj)], check=True, capture_output=True, text=True)
        objs.append(str(obj))
    return objs


class Refused(Exception):
    """The driver did not build (an #error) or the core refused to start."""


def run_driver(tmp: Path, dtype: str, X, U, valid, *, compiler: str | None = None, std: str = "c99",
               defines: tuple[str, ...] = ()) -> np.ndarray:
    """Build tests/c/export_driver.c with tmp/exported.h (as C, or as C++ with
    ``compiler``) and the C99 core, run it over the vector, return its predictions."""
    (tmp / "vector.h").write_text(vector_header(X, U, valid, dtype))
    flags = [*(["-DRHONN_SINGLE"] if dtype == "float32" else []), *defines]
    exe = tmp / "driver"
    driver = [compiler, "-x", "c++"] if compiler else [CC]
    build = subprocess.run([*driver, f"-std={std}", "-O2", "-ffp-contract=off", *STRICT, *flags, f"-I{INCLUDE}",
                            f"-I{tmp}", "-c", str(DRIVER), "-o", str(tmp / "driver.o")], capture_output=True, text=True)
    if build.returncode != 0:
        raise Refused(build.stderr)
    subprocess.run([compiler or CC, str(tmp / "driver.o"), *core_objects(tmp, dtype, flags), "-o", str(exe)],
                   check=True, capture_output=True, text=True)
    out = subprocess.run([str(exe)], capture_output=True, text=True)
    if out.returncode != 0:
        raise Refused(out.stderr)
    return np.array([[float.fromhex(v) for v in line.split()] for line in out.stdout.splitlines()])


def example_config(dtype: str, delays: bool = True, **protection) -> IdentifierConfig:
    taps = terms.delayed_taps(2, [3]) if delays else ()
    return IdentifierConfig.uniform(
        terms.first_order(3, 2) + terms.pairwise_products(3, squares=True) + taps + terms.bias(),
        n_states=3, n_inputs=2, dtype=dtype, p0=100.0, q=1e-3, r=0.2, beta=0.9, **protection)


PROTECTION = dict(covariance=CovarianceForm.UD, forgetting=0.995, p_trace_max=4000.0, reset_after=2, gate=25.0)


@pytest.mark.parametrize("protection", [{}, PROTECTION])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_exported_header_reproduces_python_predictions_bit_for_bit(tmp_path: Path, dtype: str,
                                                                   protection: dict) -> None:
    cfg = example_config(dtype, **protection)
    X, U, valid = trajectory(11, 700, 3, 2, 0.05, dtype)
    trained = Identifier(cfg)
    trained.run(X[:400], U[:400], valid[:400])
    # Python side: a fresh identifier from the trained weights and covariances
    python = Identifier(trained.as_config()).run(X[400:], U[400:], valid[400:])
    export_header(trained, tmp_path / "exported.h", name="EXPORTED")
    firmware = run_driver(tmp_path, dtype, X[400:], U[400:], valid[400:])
    assert firmware.shape == python.shape
    np.testing.assert_array_equal(firmware.astype(python.dtype), python)
    # and it really starts from the trained weights, not from w0 = 0
    untrained = Identifier(cfg).run(X[400:], U[400:], valid[400:])
    assert not np.array_equal(untrained, python)
    text = header_text(trained, "EXPORTED")
    form = "RHONN_COV_UD" if protection else "RHONN_COV_FULL"
    assert text.count(f"{form}, /* covariance */") == 2 * 3  # both literal branches, every neuron
    gate = "0x1.9000000000000p+4" if protection else "0x0.0p+0"  # 25.0: the innovation gate travels too
    assert sum(line.strip().startswith(gate) and line.endswith("/* gate (0: off) */")
               for line in text.splitlines()) == 3


# -- C++ -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("compiler", ["g++", "clang++"])
@pytest.mark.parametrize("std", ["c++11", "c++14", "c++17", "c++20"])
def test_exported_headers_compile_as_cxx_without_warnings(tmp_path: Path, compiler: str, std: str) -> None:
    exe = cxx(compiler)
    for dtype in ("float64", "float32"):
        ident = Identifier(example_config(dtype, **PROTECTION))
        X, U, valid = trajectory(5, 40, 3, 2, 0.0, dtype)
        ident.run(X, U, valid)
        export_header(ident, tmp_path / f"{dtype}.h", name=f"E_{dtype}", warm_start=(X, U, valid))
        use = tmp_path / f"use_{dtype}.cpp"
        use.write_text(f'#include "{dtype}.h"\nint main() {{ static rhonn_t net;\n'
                       f"  return rhonn_warm_start(&net, &E_{dtype}, &E_{dtype}_warm, 0) == RHONN_OK ? 0 : 1; }}\n")
        flags = ["-DRHONN_SINGLE"] if dtype == "float32" else []
        proc = subprocess.run([exe, f"-std={std}", *STRICT, *flags,
                               f'-DRHONN_USER_CAPACITY="{capacity_path(tmp_path / f"{dtype}.h").name}"',
                               f"-I{INCLUDE}", f"-I{tmp_path}", "-fsyntax-only", str(use)],
                              capture_output=True, text=True)
        assert proc.returncode == 0, f"{compiler} -std={std} {dtype}:\n{proc.stderr}"


@pytest.mark.parametrize("compiler", ["g++", "clang++"])
@pytest.mark.parametrize("std", ["c++11", "c++17"])  # decimal literals, then hexadecimal ones
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_exported_header_built_as_cxx_reproduces_python_bit_for_bit(tmp_path: Path, compiler: str, std: str,
                                                                   dtype: str) -> None:
    exe = cxx(compiler)
    X, U, valid = trajectory(12, 500, 3, 2, 0.05, dtype)
    trained = Identifier(example_config(dtype, **PROTECTION))
    trained.run(X[:300], U[:300], valid[:300])
    python = Identifier(trained.as_config()).run(X[300:], U[300:], valid[300:])
    export_header(trained, tmp_path / "exported.h", name="EXPORTED")
    firmware = run_driver(tmp_path, dtype, X[300:], U[300:], valid[300:], compiler=exe, std=std)
    np.testing.assert_array_equal(firmware.astype(python.dtype), python)


def _literal_branch(text: str, hexadecimal: bool) -> str:
    head, rest = text.split("#if !defined(__cplusplus) || __cplusplus >= 201703L\n", 1)
    hexa, rest = rest.split("#else\n", 1)
    return hexa if hexadecimal else rest.split("#endif", 1)[0]


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_decimal_literals_of_the_cxx11_branch_round_trip_bit_for_bit(dtype: str) -> None:
    rng = np.random.default_rng(3)
    L, span = 6, (40 if dtype == "float32" else 300)
    d = np.sqrt(np.exp(rng.uniform(-span, span, size=L)))  # awkward magnitudes, positive definite
    C = np.eye(L) + 0.1 * np.tanh(rng.normal(size=(L, L)) / 3)
    P = np.outer(d, d) * ((C + C.T) / 2)
    w0 = rng.normal(size=L) * np.exp(rng.uniform(-span, span, size=L))
    w0[0], w0[1] = np.nextafter(1.0, 2.0), (2.0 ** -1070 if dtype == "float64" else 1e-45)  # subnormal
    cfg = IdentifierConfig.uniform(terms.first_order(L), n_states=L, n_inputs=0, dtype=dtype, p0=1.0, q=1e-7,
                                   r=0.1 + 1e-9, beta=1 / 3)
    cfg = cfg.replace(neurons=tuple(replace(nr, w0=w0, p0=P) for nr in cfg.neurons))
    text = header_text(cfg, "E")
    number = r"-?(?:0x[0-9a-f.]+p[+-]\d+|[0-9.]+(?:e[+-]?\d+)?)f?"
    hexa, dec = (re.findall(number, re.sub(r"/\*.*?\*/", "", _literal_branch(text, h))) for h in (True, False))
    assert len(hexa) == len(dec) > 2 * L * L
    real = np.float32 if dtype == "float32" else np.float64
    n_floats = 0
    for h, d in zip(hexa, dec):
        if h.startswith(("0x", "-0x")):
            exact = real(float.fromhex(h.rstrip("f")))
            parsed = real(float(d.rstrip("f")))  # (the compiled C++11 tests check the compilers' conversion)
            assert parsed.tobytes() == exact.tobytes(), (h, d)
            n_floats += 1
        else:
            assert h == d  # integers and enum names are the same in both branches
    assert n_floats > L * L


# -- capacities ------------------------------------------------------------------------------------


def stated_size(capacity_header: str) -> int:
    m = re.search(r"sizeof\(rhonn_t\) = (\d+) bytes", capacity_header)
    assert m, capacity_header
    return int(m.group(1))


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_capacity_header_is_the_smallest_that_holds_the_identifier_and_states_its_size(tmp_path: Path,
                                                                                       dtype: str) -> None:
    X, U, valid = trajectory(21, 500, 3, 2, 0.05, dtype)
    trained = Identifier(example_config(dtype, **PROTECTION))
    trained.run(X[:300], U[:300], valid[:300])
    python = Identifier(trained.as_config()).run(X[300:], U[300:], valid[300:])
    export_header(trained, tmp_path / "exported.h", name="EXPORTED")
    cap = capacity_path(tmp_path / "exported.h")
    assert cap.name == "exported_capacity.h"
    caps = min_capacities(trained)
    assert caps["RHONN_MAX_DELAY"] == 3 and caps["RHONN_MAX_STATES"] == 3 and caps["RHONN_MAX_FACTORS"] == 2
    use_caps = ('-DRHONN_USER_CAPACITY="exported_capacity.h"',)
    # the identifier inits and steps with these capacities, bit for bit as Python
    firmware = run_driver(tmp_path, dtype, X[300:], U[300:], valid[300:], defines=use_caps)
    np.testing.assert_array_equal(firmware.astype(python.dtype), python)
    # a program built with them has the stated sizeof(rhonn_t)
    probe = tmp_path / "probe.c"
    probe.write_text('#include <stdio.h>\n#include "rhonn.h"\n'
                     'int main(void) { printf("%lu", (unsigned long)sizeof(rhonn_t)); return 0; }\n')
    flags = ["-DRHONN_SINGLE"] if dtype == "float32" else []
    subprocess.run([CC, "-std=c99", *flags, *use_caps, f"-I{tmp_path}", f"-I{INCLUDE}", str(probe), "-o",
                    str(tmp_path / "probe")], check=True)
    size = int(subprocess.run([str(tmp_path / "probe")], capture_output=True, text=True, check=True).stdout)
    assert stated_size(cap.read_text()) == size
    default = subprocess.run([CC, "-std=c99", *flags, f"-I{INCLUDE}", str(probe), "-o", str(tmp_path / "probe0")])
    assert default.returncode == 0
    assert int(subprocess.run([str(tmp_path / "probe0")], capture_output=True, text=True).stdout) > size
    # and each capacity one smaller no longer holds it: the header refuses to compile or rhonn_init refuses
    for macro, value in caps.items():
        low = {"RHONN_MAX_DELAY": 0, "RHONN_MAX_INPUTS": 1}.get(macro, 1)
        if value <= low:
            continue
        smaller, n = re.subn(rf"(#define {macro} +){value}\n", rf"\g<1>{value - 1}\n", capacity_text(trained, "E"))
        assert n == 1
        (tmp_path / "smaller.h").write_text(smaller)
        with pytest.raises(Refused, match="capacities are too small" if macro != "RHONN_MAX_ENTRIES" else
                           r"^start: RHONN_E_CONFIG"):
            run_driver(tmp_path, dtype, X[300:302], U[300:302], valid[300:302],
                       defines=('-DRHONN_USER_CAPACITY="smaller.h"',))


def test_stated_size_holds_on_a_cortex_m4(tmp_path: Path) -> None:
    """The capacity header says targets aligning double to 8 bytes lay rhonn_t
    out alike: the Cortex-M4F build (Arm EABI) has the size measured on the host."""
    arm = shutil.which("arm-none-eabi-gcc")
    nm = shutil.which("arm-none-eabi-nm")
    if not (arm and nm):
        if os.environ.get("PYRHONN_REQUIRE_CORTEX_M4") == "1":
            pytest.fail("PYRHONN_REQUIRE_CORTEX_M4=1 but arm-none-eabi-gcc/nm are not on PATH")
        pytest.skip("no arm-none-eabi-gcc")
    for dtype in ("float32", "float64"):
        export_header(example_config(dtype), tmp_path / "e.h", name="E")
        src = tmp_path / "size.c"
        src.write_text('#include "rhonn.h"\nconst unsigned char rhonn_t_size[sizeof(rhonn_t)] = {1};\n')
        flags = ["-DRHONN_SINGLE"] if dtype == "float32" else []
        subprocess.run([arm, "-std=c99", "-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16",
                        *flags, '-DRHONN_USER_CAPACITY="e_capacity.h"', f"-I{tmp_path}", f"-I{INCLUDE}", "-c",
                        str(src), "-o", str(tmp_path / "size.o")], check=True)
        out = subprocess.run([nm, "-S", str(tmp_path / "size.o")], capture_output=True, text=True, check=True).stdout
        size = int(next(line.split()[1] for line in out.splitlines() if line.endswith("rhonn_t_size")), 16)
        assert stated_size((tmp_path / "e_capacity.h").read_text()) == size


def test_capacity_header_says_why_when_the_size_cannot_be_measured(tmp_path: Path) -> None:
    cfg = IdentifierConfig.uniform(terms.first_order(2), n_states=2, n_inputs=0)
    export_header(cfg, tmp_path / "e.h", name="E", compiler="no-such-compiler-here")
    text = (tmp_path / "e_capacity.h").read_text()
    assert "not measured at export (compiler: 'no-such-compiler-here' not found)" in text
    export_header(cfg, tmp_path / "e.h", name="E", include_dir=tmp_path)
    assert "the core's rhonn.h is not there" in (tmp_path / "e_capacity.h").read_text()


def test_header_refuses_wrong_precision_small_capacity_and_another_layout(tmp_path: Path) -> None:
    cfg = IdentifierConfig.uniform(terms.first_order(2), n_states=2, n_inputs=0, dtype="float32")
    export_header(cfg, tmp_path / "exported.h", name="EXPORTED")
    src = tmp_path / "use.c"
    src.write_text('#include "exported.h"\nint main(void) { return EXPORTED.n_states == 2 ? 0 : 1; }\n')
    base = [CC, "-std=c99", "-fsyntax-only", f"-I{INCLUDE}", f"-I{tmp_path}", str(src)]
    ok = subprocess.run(base + ["-DRHONN_SINGLE"], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    wrong = subprocess.run(base, capture_output=True, text=True)
    assert wrong.returncode != 0 and "exported as float32" in wrong.stderr
    small = subprocess.run(base + ["-DRHONN_SINGLE", "-DRHONN_MAX_STATES=1"], capture_output=True, text=True)
    assert small.returncode != 0 and "capacities are too small" in small.stderr
    # the positional initialiser follows one rhonn.h layout: the header says which, and so does rhonn.h
    major, minor = LAYOUT_VERSION
    rhonn_h = (INCLUDE / "rhonn.h").read_text()
    assert f"#define RHONN_VERSION_MAJOR {major}\n" in rhonn_h and f"#define RHONN_VERSION_MINOR {minor}\n" in rhonn_h
    (tmp_path / "rhonn.h").write_text(rhonn_h.replace(f"RHONN_VERSION_MAJOR {major}",
                                                      f"RHONN_VERSION_MAJOR {major + 1}"))
    shutil.copy(INCLUDE / "rhonn_capacity.h", tmp_path)
    other = subprocess.run([CC, "-std=c99", "-fsyntax-only", "-DRHONN_SINGLE", f"-I{tmp_path}", str(src)],
                           capture_output=True, text=True)
    assert other.returncode != 0 and f"exported for the rhonn.h {major}.{minor} configuration layout" in other.stderr


# -- warm start ------------------------------------------------------------------------------------


def measured_split(valid: np.ndarray, near: int, depth: int) -> int:
    """The first split at or after ``near`` whose last ``depth`` samples are all measured."""
    return next(s for s in range(near, len(valid)) if valid[s - depth:s].all())


@pytest.mark.parametrize("delays", [True, False])
@pytest.mark.parametrize("protection", [{}, PROTECTION])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_warm_start_continues_the_python_run_bit_for_bit(tmp_path: Path, dtype: str, protection: dict,
                                                         delays: bool) -> None:
    cfg = example_config(dtype, delays, **protection)
    X, U, valid = trajectory(31, 800, 3, 2, 0.1, dtype)
    s = measured_split(valid, 400, cfg.max_delay + 1)
    ident = Identifier(cfg)
    ident.run(X[:s], U[:s], valid[:s])
    export_header(ident, tmp_path / "exported.h", name="EXPORTED", warm_start=(X[:s], U[:s], valid[:s]))
    firmware = run_driver(tmp_path, dtype, X[s:], U[s:], valid[s:], defines=("-DEXPORT_WARM",))
    python = ident.run(X[s:], U[s:], valid[s:])  # the same identifier, continuing
    np.testing.assert_array_equal(firmware.astype(python.dtype), python)


@pytest.mark.parametrize("compiler", ["g++", "clang++"])
def test_warm_start_built_as_cxx11_continues_bit_for_bit(tmp_path: Path, compiler: str) -> None:
    exe = cxx(compiler)
    cfg = example_config("float32", True, **PROTECTION)
    X, U, valid = trajectory(32, 600, 3, 2, 0.05, "float32")
    s = measured_split(valid, 300, cfg.max_delay + 1)
    ident = Identifier(cfg)
    ident.run(X[:s], U[:s], valid[:s])
    export_header(ident, tmp_path / "exported.h", name="EXPORTED", warm_start=(X[:s], U[:s], valid[:s]))
    firmware = run_driver(tmp_path, "float32", X[s:], U[s:], valid[s:], compiler=exe, std="c++11",
                          defines=("-DEXPORT_WARM",))
    np.testing.assert_array_equal(firmware, ident.run(X[s:], U[s:], valid[s:]))


def test_cold_export_of_a_running_identifier_does_not_continue_it(tmp_path: Path) -> None:
    """Why the warm start exists: the plain export (trained w0, P0) does not
    learn its first sample, so it leaves the Python run from step 0."""
    cfg = example_config("float64")
    X, U, valid = trajectory(33, 500, 3, 2, 0.0, "float64")
    ident = Identifier(cfg)
    ident.run(X[:300], U[:300], valid[:300])
    export_header(ident, tmp_path / "exported.h", name="EXPORTED")
    cold = run_driver(tmp_path, "float64", X[300:], U[300:], valid[300:])
    python = ident.run(X[300:], U[300:], valid[300:])
    assert not np.array_equal(cold[0], python[0])


def test_warm_start_refuses_samples_it_cannot_replay_exactly(tmp_path: Path) -> None:
    cfg = example_config("float64")
    D = cfg.max_delay
    X, U, valid = trajectory(34, 400, 3, 2, 0.0, "float64")
    valid[300 - 2, 1] = False
    X[300 - 2, 1] = np.nan
    ident = Identifier(cfg)
    ident.run(X[:300], U[:300], valid[:300])
    out = tmp_path / "exported.h"
    with pytest.raises(ValueError, match=rf"^warm_start valid\[298, 1\]: a dropout in the last {D + 1} samples"):
        export_header(ident, out, name="EXPORTED", warm_start=(X[:300], U[:300], valid[:300]))
    ident.run(X[300:310], U[300:310], valid[300:310])
    with pytest.raises(ValueError, match=r"^warm_start: the last 4 rows are not the samples the identifier last"):
        export_header(ident, out, name="EXPORTED", warm_start=(X[:309], U[:309], valid[:309]))
    with pytest.raises(ValueError, match=r"^warm_start X: expected dtype float64, got float32"):
        export_header(ident, out, name="EXPORTED", warm_start=(X[:310].astype("float32"), U[:310], valid[:310]))
    with pytest.raises(ValueError, match=r"^warm_start U: expected shape \(310, 2\), got \(309, 2\)"):
        export_header(ident, out, name="EXPORTED", warm_start=(X[:310], U[:309], valid[:310]))
    with pytest.raises(ValueError, match=r"^warm_start X: expected shape \(4 or more, 3\), got \(2, 3\)"):
        export_header(ident, out, name="EXPORTED", warm_start=(X[308:310], U[308:310], valid[308:310]))
    with pytest.raises(ValueError, match=r"^source: a warm start exports an Identifier's running state"):
        export_header(cfg, out, name="EXPORTED", warm_start=(X[:310], U[:310], valid[:310]))
    ident.restart()
    with pytest.raises(ValueError, match=r"^warm_start: the identifier has not stepped since"):
        export_header(ident, out, name="EXPORTED", warm_start=(X[:310], U[:310], valid[:310]))
    assert not out.exists() and not capacity_path(out).exists()  # nothing written on a refusal


# -- names -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("name, message", [("int", "is a C keyword"), ("_Bool", "is a C keyword"),
                                           ("class", "is a C\\+\\+ keyword"), ("nullptr", "is a C\\+\\+ keyword"),
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
