"""An identifier exported as an FMU (``pyrhonn export --fmu``) is a valid FMI
3.0 or 2.0 co-simulation FMU whose simulation in fmpy, one communication
step per sample, predicts bit for bit what pyrhonn.Identifier predicts on the
same samples: in float64 and in float32, as an observer (learning, with
dropouts) and as a simulator (a free run), and again after a reset. Step
sizes other than the sample period and bad exports are refused, naming what
is wrong."""
from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

fmpy = pytest.importorskip("fmpy")

from fmpy import extract, instantiate_fmu, read_model_description, simulate_fmu  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402
from fmpy.fmi3 import FMU3Slave  # noqa: E402

from pyrhonn import Identifier, IdentifierError  # noqa: E402
from pyrhonn.cli import main  # noqa: E402
from pyrhonn.configfile import ConfigFile, loads  # noqa: E402
from pyrhonn.fmu import FmuSettings, export_fmu  # noqa: E402

from strategies import trajectory  # noqa: E402

T = 0.01
N = 120
CONFIG = """
format = "pyrhonn-config"
version = 1
n_states = 2
n_inputs = 1
state_names = ["pos", "vel"]
input_names = ["force"]
x0 = [0.1, -0.2]

[defaults]
activation = "bipolar"
beta = 1.0
p0 = 10.0
q = 1e-4
r = 1e-2
eta = 1.0

[[neurons]]
terms = ["x1", "S(x1)*S(x2)", "S(x2(k-1))", "u1", "1"]

[[neurons]]
terms = ["x2", "S(x1)", "u1", "u1(k-1)"]
"""


def _cf(dtype: str = "float64") -> ConfigFile:
    cf = loads(CONFIG, source="plant.toml")
    return cf if dtype == "float64" else ConfigFile(cf.config.replace(dtype=dtype), cf.state_names, cf.input_names)


def _samples() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A small nonlinear plant, with each state missing on a few samples (NaN there)."""
    rng = np.random.default_rng(7)
    u = np.sin(0.15 * np.arange(N)) + 0.1 * rng.standard_normal(N)
    X = np.zeros((N, 2))
    for k in range(N - 1):
        X[k + 1, 0] = 0.9 * X[k, 0] + 0.1 * np.tanh(X[k, 1]) + 0.05 * u[k]
        X[k + 1, 1] = 0.8 * X[k, 1] - 0.2 * X[k, 0] + 0.1 * u[k]
    valid = np.ones((N, 2), dtype=bool)
    valid[[5, 30, 31, 32, 77], 0] = False
    valid[[12, 50, 51, 90], 1] = False
    return np.where(valid, X, np.nan), u[:, None], valid


def _table(X: np.ndarray, U: np.ndarray, valid: np.ndarray, mode: np.ndarray | None = None) -> np.ndarray:
    fields = [("time", np.float64), ("pos", np.float64), ("vel", np.float64), ("pos_valid", np.bool_),
              ("vel_valid", np.bool_), ("force", np.float64)] + ([("mode", np.int32)] if mode is not None else [])
    table = np.zeros(N, dtype=fields)
    table["time"] = np.arange(N) * T
    table["pos"], table["vel"], table["force"] = X[:, 0], X[:, 1], U[:, 0]
    table["pos_valid"], table["vel_valid"] = valid[:, 0], valid[:, 1]
    if mode is not None:
        table["mode"] = mode
    return table


OUTPUTS = ["pos_hat", "vel_hat", "pos_nis", "vel_nis", "pos_trace_p", "vel_trace_p", "pos_refused", "vel_refused"]


def _simulate(path: Path, table: np.ndarray, **kwargs: object) -> np.ndarray:
    return simulate_fmu(str(path), start_time=0.0, stop_time=N * T, output_interval=T, input=table,
                        output=OUTPUTS, **kwargs)


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype=np.float64).tobytes()


def _predictions(result: np.ndarray) -> np.ndarray:
    return np.column_stack([result["pos_hat"], result["vel_hat"]])


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[int, str], Path]:
    """One FMU per FMI version and precision."""
    folder = tmp_path_factory.mktemp("fmus")
    out = {}
    for version in (3, 2):
        for dtype in ("float64", "float32"):
            path = folder / f"plant_{version}_{dtype}.fmu"
            export_fmu(_cf(dtype), path, FmuSettings(period=T, model_identifier="plant", fmi_version=version,
                                                     units={"pos": "m", "force": "N"}))
            out[version, dtype] = path
    return out


@pytest.mark.parametrize("version", [3, 2])
def test_fmu_validates_clean_with_sources_and_binary(fmus: dict, version: int) -> None:
    path = fmus[version, "float64"]
    assert validate_fmu(str(path)) == []
    names = zipfile.ZipFile(path).namelist()
    binary = "binaries/x86_64-linux/plant.so" if version == 3 else "binaries/linux64/plant.so"
    assert binary in names and "sources/plant_fmu.c" in names and "sources/rhonn.c" in names
    assert ("sources/buildDescription.xml" in names) == (version == 3)
    assert not [n for n in names if Path(n).name.startswith("fmi")]  # the FMI headers are the importer's
    md = read_model_description(str(path))
    units = {v.name: v.unit for v in md.modelVariables}
    assert units["pos"] == units["pos_hat"] == "m" and units["force"] == "N" and units["vel"] is None
    causality = {v.name: v.causality for v in md.modelVariables}
    assert [n for n, c in causality.items() if c == "input"] == ["pos", "vel", "pos_valid", "vel_valid", "force"]
    assert [n for n, c in causality.items() if c == "output"] == OUTPUTS
    assert md.coSimulation.canHandleVariableCommunicationStepSize is False
    assert float(md.defaultExperiment.stepSize) == T


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_observer_predicts_bit_for_bit_as_the_identifier_with_dropouts(fmus: dict, version: int, dtype: str) -> None:
    X, U, valid = _samples()
    result = _simulate(fmus[version, dtype], _table(X, U, valid))
    assert len(result) == N + 1
    ident = Identifier(_cf(dtype).config)
    x0 = ident.prediction
    rows = ident.run(X.astype(dtype), U.astype(dtype), valid)
    assert _bits(_predictions(result)[0]) == _bits(x0)
    assert _bits(_predictions(result)[1:]) == _bits(rows)
    for i, name in enumerate(("pos", "vel")):
        h = ident.health(i)
        assert h.updates > 0
        assert _bits(result[f"{name}_nis"][-1]) == _bits(np.float64(h.nis))
        assert _bits(result[f"{name}_trace_p"][-1]) == _bits(np.float64(h.trace_p))
        assert result[f"{name}_refused"][-1] == h.rejected == 0


@pytest.mark.parametrize("version", [3, 2])
def test_learning_off_predicts_from_the_exported_weights(fmus: dict, version: int) -> None:
    X, U, valid = _samples()
    result = _simulate(fmus[version, "float64"], _table(X, U, valid), start_values={"learning": False})
    ident = Identifier(_cf().config)
    ident.learning = False
    assert _bits(_predictions(result)[1:]) == _bits(ident.run(X, U, valid))
    assert result["pos_trace_p"][-1] == result["pos_trace_p"][0]  # nothing learnt


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_simulator_mode_is_the_identifiers_free_run(fmus: dict, version: int, dtype: str) -> None:
    """Observer for the first K samples (learning), then simulator (the mode a
    tunable parameter switched by the input table): the free run from K."""
    X, U, valid = _samples()
    K = 60
    mode = np.where(np.arange(N) < K, 0, 1).astype(np.int32)
    result = _simulate(fmus[version, dtype], _table(X, U, valid, mode))
    ident = Identifier(_cf(dtype).config)
    Xd, Ud = X.astype(dtype), U.astype(dtype)
    rows = np.vstack([ident.run(Xd[:K], Ud[:K], valid[:K]),
                      ident.run(Xd[K:], Ud[K:], np.zeros((N - K, 2), dtype=bool))])
    assert _bits(_predictions(result)[1:]) == _bits(rows)
    learnt_only = Identifier(_cf(dtype).config)
    learnt_only.run(Xd[:K], Ud[:K], valid[:K])
    assert [h.updates for h in ident.healths] == [h.updates for h in learnt_only.healths]  # none in the free run


def test_a_refused_learning_update_steps_the_sample_frozen_and_is_counted(tmp_path: Path) -> None:
    """float32 with P0 / R = 1e14 and no Q: some updates would leave P indefinite
    and the core refuses them. The simulation goes on: each such sample is
    stepped with learning frozen, as the identifier below does by hand."""
    text = CONFIG.replace("p0 = 10.0", "p0 = 1e6").replace("r = 1e-2", "r = 1e-8").replace("q = 1e-4", "q = 0.0")
    cf = loads(text, source="stiff.toml")
    cf = ConfigFile(cf.config.replace(dtype="float32"), cf.state_names, cf.input_names)
    path = tmp_path / "stiff.fmu"
    export_fmu(cf, path, FmuSettings(period=T, model_identifier="stiff"))
    X, U, valid = _samples()
    messages: list[str] = []
    result = _simulate(path, _table(X, U, valid), logger=lambda *args: messages.append(str(args[-1])))
    ident = Identifier(cf.config)
    rows = []
    for k in range(N):
        x, u = X[k].astype(np.float32), U[k].astype(np.float32)
        try:
            rows.append(ident.step(x, u, valid[k]))
        except IdentifierError:
            ident.learning = False
            rows.append(ident.step(x, u, valid[k]))
            ident.learning = True
    refused = [h.rejected for h in ident.healths]
    assert sum(refused) > 0
    assert [result["pos_refused"][-1], result["vel_refused"][-1]] == refused
    assert _bits(_predictions(result)[1:]) == _bits(np.array(rows))
    assert sum("learning update was refused" in m for m in messages) == sum(refused)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**16), dropout=st.sampled_from([0.0, 0.1, 0.4]), free_from=st.integers(0, N),
       learning=st.booleans(), dtype=st.sampled_from(["float32", "float64"]))
def test_any_trajectory_dropouts_and_free_run_match_the_identifier(fmus: dict, seed: int, dropout: float,
                                                                   free_from: int, learning: bool,
                                                                   dtype: str) -> None:
    X, U, valid = trajectory(seed, N, 2, 1, dropout)
    mode = (np.arange(N) >= free_from).astype(np.int32)
    result = _simulate(fmus[3, dtype], _table(X, U, valid, mode), start_values={"learning": learning})
    ident = Identifier(_cf(dtype).config)
    ident.learning = learning
    Xd, Ud, K = X.astype(dtype), U.astype(dtype), free_from
    parts = [ident.run(Xd[:K], Ud[:K], valid[:K]) if K else np.zeros((0, 2), dtype),
             ident.run(Xd[K:], Ud[K:], np.zeros((N - K, 2), dtype=bool)) if K < N else np.zeros((0, 2), dtype)]
    assert _bits(_predictions(result)[1:]) == _bits(np.vstack(parts))


def test_simulator_from_the_start_needs_no_measurements(fmus: dict) -> None:
    X, U, valid = _samples()
    result = _simulate(fmus[3, "float64"], _table(np.full_like(X, np.nan), U, valid), start_values={"mode": 1})
    ident = Identifier(_cf().config)
    rows = ident.run(np.zeros_like(X), U, np.zeros_like(valid))
    assert _bits(_predictions(result)[1:]) == _bits(rows)


@pytest.mark.parametrize("version", [3, 2])
def test_reset_starts_the_identifier_over(fmus: dict, version: int, tmp_path: Path) -> None:
    path = fmus[version, "float64"]
    unzipped = extract(str(path), unzipdir=str(tmp_path / "fmu"))
    md = read_model_description(unzipped)
    fmu = instantiate_fmu(unzipped, md, fmi_type="CoSimulation")
    X, U, valid = _samples()
    try:
        first = _simulate(Path(unzipped), _table(X, U, valid), model_description=md, fmu_instance=fmu)
        fmu.reset()
        again = _simulate(Path(unzipped), _table(X, U, valid), model_description=md, fmu_instance=fmu)
    finally:
        fmu.freeInstance()
    rows = Identifier(_cf().config).run(X, U, valid)
    assert _bits(_predictions(first)[1:]) == _bits(rows)
    assert _bits(_predictions(again)[1:]) == _bits(rows)


def _stepper(path: Path, tmp_path: Path, messages: list[str]):  # type: ignore[no-untyped-def]
    unzipped = extract(str(path), unzipdir=str(tmp_path / "fmu"))
    md = read_model_description(unzipped)
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier="plant", instanceName="plant")

    def log(env, status, category, message):  # type: ignore[no-untyped-def]
        messages.append(message.decode())

    fmu.instantiate(logMessage=log)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    return fmu, md


def test_a_step_other_than_the_period_is_refused_with_a_message(fmus: dict, tmp_path: Path) -> None:
    messages: list[str] = []
    fmu, md = _stepper(fmus[3, "float64"], tmp_path, messages)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    try:
        with pytest.raises(FMICallException):
            fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=2 * T)
        assert "communicationStepSize 0.02" in messages[-1] and "sample period 0.01" in messages[-1]
        with pytest.raises(FMICallException):  # a skipped communication point
            fmu.doStep(currentCommunicationPoint=T, communicationStepSize=T)
        assert "currentCommunicationPoint" in messages[-1]
        before = fmu.getFloat64([vr["pos_hat"]])
        fmu.setFloat64([vr["pos"]], [float("nan")])
        with pytest.raises(FMICallException):
            fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=T)
        assert "pos = nan" in messages[-1] and "pos_valid" in messages[-1]
        assert fmu.getFloat64([vr["pos_hat"]]) == before  # nothing stepped
        with pytest.raises(FMICallException):
            fmu.setInt32([vr["mode"]], [2])
        assert "mode: 2 is not a mode" in messages[-1]
        with pytest.raises(FMICallException):
            fmu.fmi3GetFloat64(fmu.component, None, 1, None, 1)
        assert "valueReferences or values is NULL" in messages[-1]
        with pytest.raises(FMICallException):
            fmu.getFloat64([vr["learning"]])
        assert "value reference 1 is not a Float64" in messages[-1]
        fmu.setFloat64([vr["pos"]], [0.5])
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=T)  # the period itself steps
        assert fmu.getFloat64([md.modelVariables[0].valueReference]) == [T]
    finally:
        fmu.terminate()
        fmu.freeInstance()


NO_INPUTS = """
format = "pyrhonn-config"
version = 1
n_states = 1
n_inputs = 0
state_names = ["level"]
x0 = [0.25]

[defaults]
p0 = 10.0
q = 1e-4
r = 1e-2

[[neurons]]
terms = ["x1", "S(x1)", "S(x1(k-2))", "1"]
"""
STRICT = ["-std=c99", "-fsyntax-only", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wshadow",
          "-Wdouble-promotion", "-Werror"]


@pytest.fixture(scope="module")
def tanks(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """A plant without inputs, per FMI version."""
    folder = tmp_path_factory.mktemp("tanks")
    for version in (3, 2):
        export_fmu(loads(NO_INPUTS, source="tank.toml"), folder / f"tank{version}.fmu",
                   FmuSettings(period=0.5, model_identifier="tank", fmi_version=version))
    return {version: folder / f"tank{version}.fmu" for version in (3, 2)}


@pytest.mark.parametrize("version", [3, 2])
def test_sources_compile_without_warnings_under_the_projects_flags(fmus: dict, tanks: dict, version: int,
                                                                   tmp_path: Path) -> None:
    """The FMU's own sources (sources/MODEL_fmu.c with what it includes), both
    precisions, and a plant without inputs too."""
    from pyrhonn.fmu import fmi_headers

    for path, ident in ((fmus[version, "float64"], "plant"), (fmus[version, "float32"], "plant"),
                        (tanks[version], "tank")):
        folder = tmp_path / path.stem
        zipfile.ZipFile(path).extractall(folder)
        build = subprocess.run(["cc", *STRICT, f"-I{folder / 'sources'}", f"-I{fmi_headers(version)}",
                                str(folder / "sources" / f"{ident}_fmu.c")], capture_output=True, text=True)
        assert build.returncode == 0, build.stderr


def test_a_plant_without_inputs_simulates_as_the_identifier(tanks: dict) -> None:
    path = tanks[3]
    cf = loads(NO_INPUTS, source="tank.toml")
    level = 1.0 + 0.5 * np.sin(0.2 * np.arange(40))
    valid = np.arange(40) % 9 != 4
    table = np.zeros(40, dtype=[("time", np.float64), ("level", np.float64), ("level_valid", np.bool_)])
    table["time"], table["level"], table["level_valid"] = 0.5 * np.arange(40), level, valid
    result = simulate_fmu(str(path), stop_time=20.0, output_interval=0.5, input=table, output=["level_hat"])
    rows = Identifier(cf.config).run(level[:, None], None, valid[:, None])
    assert _bits(result["level_hat"]) == _bits(np.concatenate([[0.25], rows[:, 0]]))


def test_fmi2_refuses_a_step_other_than_the_period(fmus: dict, tmp_path: Path) -> None:
    unzipped = extract(str(fmus[2, "float64"]), unzipdir=str(tmp_path / "fmu"))
    md = read_model_description(unzipped)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier="plant", instanceName="plant")
    fmu.instantiate(callbacks=None)
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        with pytest.raises(FMICallException):
            fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=T / 2)
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=T)
        with pytest.raises(FMICallException):  # the same communication point again
            fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=T)
        fmu.doStep(currentCommunicationPoint=T, communicationStepSize=T)
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_a_float32_fmu_refuses_a_measurement_beyond_float32(fmus: dict, tmp_path: Path) -> None:
    messages: list[str] = []
    fmu, md = _stepper(fmus[3, "float32"], tmp_path, messages)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    try:
        fmu.setFloat64([vr["vel"], vr["force"]], [1e300, 0.5])
        with pytest.raises(FMICallException):
            fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=T)
        assert "vel = 1e+300" in messages[-1] and "finite in the FMU's precision" in messages[-1]
        fmu.setBoolean([vr["vel_valid"]], [False])  # not measured: its value is not read
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=T)
    finally:
        fmu.terminate()
        fmu.freeInstance()


# -- the command line ------------------------------------------------------------------------------


def _write_config(tmp_path: Path, text: str = CONFIG, name: str = "plant.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _write_recording(tmp_path: Path, X: np.ndarray, U: np.ndarray, valid: np.ndarray) -> Path:
    data = tmp_path / "rec.csv"
    rows = ["pos,vel,force,pos_valid,vel_valid"] + [
        f"{float(x[0])!r},{float(x[1])!r},{float(u[0])!r},{int(v[0])},{int(v[1])}"
        for x, u, v in zip(np.where(valid, X, 0.0), U, valid)]
    data.write_text("\n".join(rows) + "\n")
    return data


def test_cli_exports_an_fmu_trained_on_a_recording(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    X, U, valid = _samples()
    data = _write_recording(tmp_path, X, U, valid)
    out = tmp_path / "plant.fmu"
    assert main(["export", "--config", str(_write_config(tmp_path)), "--fmu", str(out), "--period", "0.01",
                 "--data", str(data), "--fit-rows", ":60", "--units", "pos=m"]) == 0
    assert "FMI 3.0 co-simulation FMU plant" in capsys.readouterr().out
    assert validate_fmu(str(out)) == []
    trained = Identifier(_cf().config)
    trained.run(np.where(valid, X, 0.0)[:60], U[:60], valid[:60])
    ident = Identifier(trained.as_config())
    result = _simulate(out, _table(X, U, valid))
    assert _bits(_predictions(result)[1:]) == _bits(ident.run(X, U, valid))


def test_a_warm_started_fmu_continues_the_recordings_run(tmp_path: Path) -> None:
    """--warm-start: the FMU starts from the running state the recording left,
    and after a reset starts from it again."""
    X, U, valid = _samples()
    data = _write_recording(tmp_path, X, U, valid)
    out = tmp_path / "plant.fmu"
    assert main(["export", "--config", str(_write_config(tmp_path)), "--fmu", str(out), "--period", "0.01",
                 "--data", str(data), "--fit-rows", ":60", "--warm-start"]) == 0
    assert "sources/rhonn_warm.c" in zipfile.ZipFile(out).namelist()
    ident = Identifier(_cf().config)
    ident.run(np.where(valid, X, 0.0)[:60], U[:60], valid[:60])
    now = ident.prediction
    rows = ident.run(X[60:], U[60:], valid[60:])
    unzipped = extract(str(out), unzipdir=str(tmp_path / "fmu"))
    md = read_model_description(unzipped)
    fmu = instantiate_fmu(unzipped, md, fmi_type="CoSimulation")
    table = _table(np.vstack([X[60:], X[:60]]), np.vstack([U[60:], U[:60]]), np.vstack([valid[60:], valid[:60]]))
    try:
        for _ in range(2):  # the second time after a reset
            result = simulate_fmu(unzipped, start_time=0.0, stop_time=(N - 60) * T, output_interval=T, input=table,
                                  output=OUTPUTS, model_description=md, fmu_instance=fmu)
            assert _bits(_predictions(result)[0]) == _bits(now)
            assert _bits(_predictions(result)[1:]) == _bits(rows)
            fmu.reset()
    finally:
        fmu.freeInstance()


def test_cli_fmi2_from_the_shipped_name(tmp_path: Path) -> None:
    out = tmp_path / "ex1.fmu"
    assert main(["export", "--config", "example1", "--fmu", str(out), "--fmi-version", "2", "--period", "0.2",
                 "--dtype", "float32"]) == 0
    assert validate_fmu(str(out)) == []
    assert read_model_description(str(out)).fmiVersion == "2.0"


def test_cli_refuses_bad_exports_and_keeps_the_previous_file(tmp_path: Path, cli_error,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = str(_write_config(tmp_path))
    out = tmp_path / "plant.fmu"
    out.write_bytes(b"previous")
    base = ["export", "--config", cfg, "--fmu", str(out)]
    assert "--period: needed" in cli_error(base)
    assert "--period: must be > 0" in cli_error(base + ["--period", "-1"])
    assert "--fmi-version" in cli_error(base + ["--period", "0.01", "--fmi-version", "4"])
    assert "--units" in cli_error(base + ["--period", "0.01", "--units", "speed=m"])
    assert "--warm-start: needs --data" in cli_error(base + ["--period", "0.01", "--warm-start"])
    assert "--period: only with --fmu" in cli_error(["export", "--config", cfg, "--out", str(tmp_path / "a.h"),
                                                     "--period", "0.01"])
    assert "expected a file name ending in .fmu" in cli_error(["export", "--config", cfg, "--fmu",
                                                               str(tmp_path / "a.zip"), "--period", "0.01"])
    assert "does not exist" in cli_error(["export", "--config", cfg, "--fmu", str(tmp_path / "no" / "a.fmu"),
                                          "--period", "0.01"])
    assert "must be a C identifier" in cli_error(["export", "--config", cfg, "--fmu", str(tmp_path / "my-plant.fmu"),
                                                  "--period", "0.01"])
    monkeypatch.setenv("CC", "no-such-compiler-cc")
    assert "compiler: 'no-such-compiler-cc' not found" in cli_error(base + ["--period", "0.01"])
    monkeypatch.setenv("CC", "false")  # a compiler that fails: the build stops, nothing is written
    assert "compiler: false failed" in cli_error(base + ["--period", "0.01"])
    monkeypatch.delenv("CC")
    clash = CONFIG.replace('state_names = ["pos", "vel"]', 'state_names = ["pos", "pos_hat"]')
    assert "pos_hat" in cli_error(["export", "--config", str(_write_config(tmp_path, clash, "clash.toml")), "--fmu", str(out),
                                   "--period", "0.01"])
    assert out.read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clash.toml", "plant.fmu", "plant.toml"]  # no leftovers
    # a folder nobody can create files in, root included
    assert "cannot be written" in cli_error(["export", "--config", cfg, "--fmu", "/proc/plant.fmu", "--period", "0.01"])


def test_settings_refuse_what_an_fmu_cannot_express() -> None:
    with pytest.raises(ValueError, match="fmi_version: expected 3 or 2"):
        FmuSettings(period=T, model_identifier="plant", fmi_version=1)
    with pytest.raises(ValueError, match="period"):
        FmuSettings(period=float("inf"), model_identifier="plant")
    with pytest.raises(ValueError, match="mode"):
        FmuSettings(period=T, model_identifier="plant", mode="replay")
    with pytest.raises(ValueError, match="name"):
        FmuSettings(period=T, model_identifier="int")
    for clash in ("rhonn", "fmi3Functions", "fmi3DoStep", "fmu_start", "pyrhonn_fmu"):
        with pytest.raises(ValueError, match="would clash with the FMU's own sources"):
            FmuSettings(period=T, model_identifier=clash)


def test_the_docs_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                               capsys: pytest.CaptureFixture) -> None:
    """docs/fmu.md: its export command, then its Python examples in order, in one folder."""
    text = (Path(__file__).resolve().parent.parent / "docs" / "fmu.md").read_text()
    command = next(line for line in text.splitlines() if line.startswith("pyrhonn export --config example1"))
    example = "".join(block.split("```", 1)[0] for block in text.split("```python\n")[1:])
    monkeypatch.chdir(tmp_path)
    assert main(command.split()[1:]) == 0
    exec(compile(example, "docs/fmu.md", "exec"), {})
    out = capsys.readouterr().out
    assert "201 steps, last NIS of x1" in out and "Warning" not in out
