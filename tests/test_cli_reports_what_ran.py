"""What the commands print and leave behind describes the run that just
happened: `identify --no-plots` leaves no earlier run's plot beside its
outputs, `tune` shows each neuron's values when they differ and counts the
trials that run at once with `--batch`."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from pyrhonn.cli import main
from pyrhonn.configfile import load_shipped, save_config
from pyrhonn.plants import Trajectory, oscillator
from test_tune import write_csv


@pytest.fixture(scope="module")
def traj() -> Trajectory:
    return oscillator.simulate(dt=0.2, horizon=10.0)


def test_identify_without_plots_removes_the_plots_an_earlier_run_left(tmp_path: Path, traj: Trajectory) -> None:
    data, out = tmp_path / "d.csv", tmp_path / "out"
    write_csv(data, traj)
    out.mkdir()
    earlier = [out / f"{name}.png" for name in traj.state_names]
    for png in earlier:
        png.write_bytes(b"an earlier run's plot")
    (out / "notes.png").write_bytes(b"not a plot of identify")
    assert main(["identify", str(data), "--config", "example1", "--out", str(out), "--no-plots"]) == 0
    assert not [p.name for p in earlier if p.exists()]
    assert (out / "notes.png").read_bytes() == b"not a plot of identify"
    assert (out / "metrics.json").is_file() and not (out / "INCOMPLETE").exists()


def test_tune_shows_each_neurons_values_when_the_kept_base_holds_its_own(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cf = load_shipped("example1")
    neurons = tuple(replace(nr, p0=10.0 ** (i + 1)) for i, nr in enumerate(cf.config.neurons))
    save_config(cf.config.replace(neurons=neurons), tmp_path / "base.toml")
    # a range where every trial diverges: the base config, with its own P0 per neuron, is kept
    code = main(["tune", "--example", "example1", "--horizon", "10", "--config", str(tmp_path / "base.toml"),
                 "--out", str(tmp_path / "t.toml"), "--trials", "2", "--params", "p0", "--range", "p0=1e31:1e36"])
    out = capsys.readouterr().out
    assert code == 0, out
    values = out[out.index("values (base):"):].splitlines()
    assert "(every neuron)" not in values[1]
    rows = {line.split()[0]: line.split()[1] for line in values[2:2 + len(neurons)]}
    assert list(rows.values()) == ["10", "100", "1e+03", "1e+04"]


def test_tune_shows_shared_values_once_when_every_neuron_holds_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["tune", "--example", "example1", "--horizon", "10", "--config", "example1",
                 "--out", str(tmp_path / "t.toml"), "--trials", "2", "--params", "eta", "--range", "eta=1e-9:2e-9"])
    out = capsys.readouterr().out
    assert code == 0, out
    line = out.splitlines()[out.splitlines().index(next(x for x in out.splitlines() if x.startswith("tuned values")
                                                         or x.startswith("values (base)"))) + 1]
    assert line.strip().startswith("eta = ") and line.endswith("(every neuron)")


@pytest.mark.parametrize(("options", "said"), [([], "1 at a time"), (["--batch", "4"], "4 at a time (1 worker, 4 "),
                                               (["--batch", "2", "--n-jobs", "2"], "4 at a time (2 workers, 2 ")])
def test_tune_counts_the_trials_that_run_at_once(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 options: list[str], said: str) -> None:
    code = main(["tune", "--example", "example1", "--horizon", "10", "--config", "example1",
                 "--out", str(tmp_path / "t.toml"), "--trials", "1", "--params", "eta", *options])
    err = capsys.readouterr().err
    assert code == 0, err
    assert said in err.splitlines()[0]
