"""hil replay of another identifier than the LIM: a small plant (2 states, 1 input
delayed by 2 samples) selected from a synthetic recording with pyrhonn select,
exported with its DBC (pyrhonn export --dbc), and replayed from the recording as
that DBC's Measurement frames against the firmware built for it: the Python twin
on the virtual bus, the C runner over udp_multicast, the Cortex-M4F image under
QEMU; bit-exact against the offline Identifier (the M4: frame for frame against
the twin), every frame accounted for, verdicts and JUnit."""
from __future__ import annotations

import dataclasses
import json
import os
import shlex
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

pytest.importorskip("can")
cantools = pytest.importorskip("cantools")

from pyrhonn.cli import main as pyrhonn_main  # noqa: E402
from pyrhonn.firmware import FirmwareApp, Protocol, lim_protocol  # noqa: E402

from hil.rig import read_log  # noqa: E402
from hil.scenario import Scenario  # noqa: E402
from hil.score import score  # noqa: E402

from docs_blocks import blocks_by, commands  # noqa: E402
from source_scripts import load_script  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
FW = ROOT / "firmware_sim"


@pytest.fixture(scope="module")
def twin(exported):
    """The firmware application compiled for the exported DBC (cached per DBC and sources, in the cache
    hil replay uses: the replay below finds it there)."""
    build_twin = load_script(FW / "tools" / "build_twin.py", "_test_build_twin")
    try:
        return build_twin.protocol(exported["dbc"])
    except Exception as exc:  # noqa: BLE001 - no compiler here
        pytest.skip(f"the twin cannot be built here: {exc}")


def test_the_exported_dbc_carries_the_config_states_and_inputs_in_order(exported) -> None:
    proto = Protocol.from_dbc(exported["dbc"])
    assert proto.states == ("y1", "y2") and proto.inputs == ("u",)
    assert lim_protocol().states == ("Qm", "V", "LambdaA", "LambdaB", "Ia", "Ib")
    msg = proto.measurement_message(7, [0.25, -0.5], [0.75], [True, False])
    x, u, valid = proto.decode_measurement(bytes(msg.data))
    assert x.tolist() == [0.25, -0.5] and u.tolist() == [0.75] and valid.tolist() == [True, False]


def test_the_generated_layout_names_the_dbc_signals_and_refuses_a_scale_the_float32_firmware_cannot_convert(
        exported, tmp_path) -> None:
    gen = load_script(FW / "tools" / "generate_protocol.py", "_test_generate_protocol")
    text = gen.layout_header(exported["dbc"])
    assert "#define FW_N_STATES 2u" in text and "#define FW_N_INPUTS 1u" in text
    assert "(out).u[0] = FW_DECODE(rhonn_id_measurement_u_decode" in text
    bad = tmp_path / "bad.dbc"
    bad.write_text(exported["dbc"].read_text().replace("(5e-05,0)", "(0.1,0)", 1))
    with pytest.raises(ValueError, match=r"Measurement\.y\d: scale 0\.1 is not 1/N"):
        gen.layout_header(bad)
    old = tmp_path / "old.dbc"           # exported before rhonn_id 2.2: its Health has no Gated
    old.write_text("\n".join(line for line in exported["dbc"].read_text().splitlines() if " Gated " not in line))
    with pytest.raises(ValueError, match="Health: no Gated signal .*export it again"):
        gen.layout_header(old)
    with pytest.raises(SystemExit):   # never over the committed LIM files
        gen.main(["--dbc", str(exported["dbc"]), "-o", str(FW / "generated")])


def test_the_twin_refuses_a_config_of_another_shape_and_a_protocol_without_firmware(exported, twin) -> None:
    with pytest.raises(ValueError, match="protocol carries 2 states and 1 inputs"):
        FirmwareApp(None, Scenario().reference_config(), protocol=twin)
    with pytest.raises(ValueError, match="protocol: expected a Protocol with the firmware"):
        FirmwareApp(None, Scenario().reference_config(), protocol=Protocol.from_dbc(exported["dbc"]))


def test_a_replay_on_the_virtual_bus_is_bit_exact_and_judged_by_the_thresholds(exported, twin, tmp_path,
                                                                                monkeypatch) -> None:
    monkeypatch.chdir(ROOT)   # the firmware sources: a checkout
    (tmp_path / "ci.toml").write_text(f"""
[scenario]
identifier = "{exported['config']}"
dbc = "{exported['dbc']}"
trajectory = "{exported['data']}"
duration = 0.3
frame_loss = 0.01
seed = 3
hold_states = [1]
hold_start = 0.1
hold_duration = 0.03

[thresholds]
lost_frames = 0
rmse = {{ y1 = 0.05, y2 = 1e-9 }}
""")
    argv = ["hil", "replay", "--transport", "virtual", "--scenario", str(tmp_path / "ci.toml"), "--quiet",
            "--log", str(tmp_path / "run.blf"), "--junit", str(tmp_path / "junit.xml")]
    assert pyrhonn_main(argv) == 1      # y2's limit is out of reach
    cases = {tc.get("name"): tc for tc in ET.parse(tmp_path / "junit.xml").getroot().iter("testcase")}
    assert set(cases) == {"rmse.y1", "rmse.y2", "lost_frames", "frames_accounted", "bit_exact"}
    assert cases["rmse.y1"].find("failure") is None and cases["bit_exact"].find("failure") is None
    assert cases["frames_accounted"].find("failure") is None
    assert cases["rmse.y2"].find("failure") is not None

    rec = read_log(tmp_path / "run.blf")
    sc = rec.scenario
    assert sc.identifier == str(exported["config"]) and sc.hold_states == (1,)
    report = score(rec, reference=sc.reference_config())
    f = report["frames"]
    assert f["lost_injected"] > 0 and f["accounted"] and f["rejected_seq_jump"] > 0
    assert report["bit_exact"]["equal"] and report["bit_exact"]["checked"] == f["answered"]
    assert report["states"] == ["y1", "y2"] and report["not_valid"]["y2"]["held"] == 100
    assert report["identification"]["y1"]["rmse"] < 0.05
    import matplotlib.pyplot as plt

    from hil.figures import build_figures

    figs = build_figures(report)
    assert {"y1.png", "y2.png"} <= set(figs) and "position.png" not in figs
    assert figs["y2.png"].axes[0].get_title() == "y2: real vs identified, virtual"
    for fig in figs.values():
        plt.close(fig)
    # the estimates are the offline identifier's: a different config is not
    cfg = sc.reference_config()
    other = cfg.replace(neurons=tuple(dataclasses.replace(n, r=n.r * 2) for n in cfg.neurons))
    assert not score(rec, reference=other)["bit_exact"]["equal"]


def test_a_replay_over_udp_multicast_runs_the_c_runner_built_for_the_identifier(exported, tmp_path,
                                                                              monkeypatch) -> None:
    d = exported["dir"]
    build_runner = load_script(FW / "linux" / "build_runner.py", "_test_build_runner")
    try:   # built once per config, DBC and sources (the CI's second run reuses it)
        exe = build_runner.cached_for(exported["config"], exported["dbc"])
    except RuntimeError as exc:
        pytest.skip(f"no C compiler: {exc}")
    assert "static const rhonn_config FW_IDENTIFIER" in (exe.parent / "fw_identifier.h").read_text()
    argv = ["hil", "replay", "--transport", "udp_multicast", "--runner", str(exe), "--identifier",
            str(exported["config"]), "--dbc", str(exported["dbc"]), "--trajectory", str(exported["data"]),
            "--duration", "0.3", "--frame-loss", "0.01", "--seed", "5", "--quiet", "--log", str(d / "udp.blf")]
    monkeypatch.chdir(tmp_path)
    assert pyrhonn_main(argv) == 0
    rec = read_log(d / "udp.blf")
    report = score(rec, reference=rec.scenario.reference_config())
    assert report["bit_exact"]["equal"] and report["bit_exact"]["checked"] > 900
    assert report["frames"]["accounted"] and report["firmware"]["measurements"] == report["frames"]["answered"]


def test_an_identifier_scenario_refuses_a_dbc_of_other_signals_and_the_lim_encoder_model(exported, tmp_path,
                                                                                        cli_error) -> None:
    base = {"identifier": str(exported["config"]), "dbc": str(exported["dbc"]), "trajectory": str(exported["data"]),
            "encoder_resolution": 0.0, "velocity_from_position": False, "hold_duration": 0.0, "duration": 0.1}
    assert Scenario(**base).state_names == ("y1", "y2")
    with pytest.raises(ValueError, match="encoder_resolution: the LIM's encoder model"):
        Scenario(**{**base, "encoder_resolution": 1e-5})
    with pytest.raises(ValueError, match="dbc: an identifier's config file and its DBC go together"):
        Scenario(**{**base, "dbc": ""})
    with pytest.raises(ValueError, match="hold_states: expected state indices 0..1"):
        Scenario(**{**base, "hold_states": (2,)})
    other = tmp_path / "other.dbc"
    other.write_text(exported["dbc"].read_text().replace("y2", "z2"))
    with pytest.raises(ValueError, match=r"dbc: .* carries states \['y1', 'z2'\]"):
        Scenario(**{**base, "dbc": str(other)})
    err = cli_error(["hil", "replay", "--transport", "virtual", "--identifier", str(exported["config"]),
                     "--dbc", str(exported["dbc"]), "--duration", "0.1"])
    assert "trajectory" in err
    f64 = tmp_path / "f64.toml"
    f64.write_text(exported["config"].read_text().replace('dtype = "float32"', 'dtype = "float64"'))
    with pytest.raises(ValueError, match="identifier: .*dtype is 'float64'; the firmware runs the float32 core"):
        Scenario(**{**base, "identifier": str(f64)})


def test_the_updates_the_innovation_gate_skipped_show_in_the_health_frames_the_runner_json_and_the_report(
        exported, twin, tmp_path, monkeypatch) -> None:
    # a gate of 0.5 on e^2/s: about half the updates of a consistent filter exceed it
    gated = tmp_path / "gated.toml"
    gated.write_text(exported["config"].read_text().replace("\nr = ", "\ngate = 0.5\nr = "))
    assert Scenario(identifier=str(gated), dbc=str(exported["dbc"]), trajectory=str(exported["data"]),
                    encoder_resolution=0.0, velocity_from_position=False).reference_config().neurons[1].gate == 0.5
    build_runner = load_script(FW / "linux" / "build_runner.py", "_test_build_runner")
    try:
        exe = build_runner.cached_for(gated, exported["dbc"])
    except RuntimeError as exc:
        pytest.skip(f"no C compiler: {exc}")
    monkeypatch.chdir(tmp_path)
    for transport in ("virtual", "udp_multicast"):
        out = tmp_path / transport
        argv = ["hil", "replay", "--transport", transport, "--identifier", str(gated), "--dbc", str(exported["dbc"]),
                "--trajectory", str(exported["data"]), "--duration", "0.15", "--quiet", "--out", str(out), "--log",
                str(tmp_path / f"{transport}.blf")]
        if transport == "udp_multicast":
            argv += ["--runner", str(exe)]
        assert pyrhonn_main(argv) == 0
        report = json.loads((out / "report.json").read_text())
        assert report["bit_exact"]["equal"]      # the offline Identifier gates the same updates
        health = report["health"]                # the Health frames after the final Diagnostics
        assert [h["neuron"] for h in health] == [0, 1] and all(h["gated"] > 0 for h in health)
        rec = read_log(tmp_path / f"{transport}.blf")
        r = score(rec, reference=rec.scenario.reference_config())   # the offline twin, on the frames sent
        assert r["_series"]["health"]["gated"][-1].tolist() == [h["gated"] for h in health]
        text = (out / "report.txt").read_text()
        assert f"gated {health[0]['gated']}" in text and f"gated {health[1]['gated']}" in text
        assert (out / "health.png").is_file()
        if transport == "udp_multicast":             # the runner's own JSON summary
            stats = report["firmware_side"]["stats"]
            assert [h["gated"] for h in stats["health"]] == [h["gated"] for h in health]
    import matplotlib.pyplot as plt

    from hil.figures import build_figures

    figs = build_figures(r)
    assert f"gated updates {sum(h['gated'] for h in health)}" in figs["health.png"].axes[2].get_title()
    for fig in figs.values():
        plt.close(fig)


@pytest.mark.parametrize("firmware, process", [("runner", "rhonn_runner"), ("python", "hil.firmware_node")])
def test_hil_bench_and_the_python_node_run_another_identifier_bit_exact(exported, twin, firmware, process,
                                                                        capsys) -> None:
    argv = ["hil", "bench", "--cycles", "200", "--firmware", firmware, "--identifier", str(exported["config"]),
            "--dbc", str(exported["dbc"]), "--trajectory", str(exported["data"]), "--json"]
    try:
        assert pyrhonn_main(argv) == 0
    except Exception as exc:  # noqa: BLE001 - only where no runner can be built
        if firmware == "runner" and "cannot build rhonn_runner" in str(exc):
            pytest.skip(str(exc))
        raise
    r = json.loads(capsys.readouterr().out)
    assert r["firmware_side"]["firmware"] == process and "fallback" not in r["firmware_side"]
    assert r["states"] == ["y1", "y2"] and r["frames"]["sent"] == 200 and r["frames"]["accounted"]
    assert r["bit_exact"]["equal"] and r["bit_exact"]["checked"] == r["frames"]["answered"] == 200
    assert r["firmware"]["measurements"] == 200


def test_hil_bench_and_the_python_node_refuse_a_half_given_or_mismatched_identifier(exported, twin, tmp_path,
                                                                                      cli_error, capsys) -> None:
    from hil import firmware_node

    base = ["hil", "bench", "--cycles", "200", "--transport", "virtual"]
    assert "--dbc: only with --identifier" in cli_error([*base, "--dbc", str(exported["dbc"])])
    err = cli_error([*base, "--identifier", str(exported["config"]), "--trajectory", str(exported["data"])])
    assert "--dbc: an identifier's config file and its DBC go together" in err
    err = cli_error([*base, "--identifier", str(exported["config"]), "--dbc", str(exported["dbc"])])
    assert "--trajectory: an identifier's plant is a recording" in err
    err = cli_error(["hil", "bench", "--cycles", "5000", "--transport", "virtual", "--identifier",
                     str(exported["config"]), "--dbc", str(exported["dbc"]), "--trajectory", str(exported["data"])])
    assert "--trajectory:" in err and "covers t = 0..0.5997 s" in err
    node = ["--channel", "239.74.163.2", "--port", "29999", "--duration", "0"]
    assert firmware_node.main([*node, "--identifier", str(exported["config"])]) == 2
    assert "--identifier, --dbc: an identifier's config file and its DBC go together" in capsys.readouterr().err
    lim = ROOT / "pyrhonn" / "configs" / "firmware-lim.toml"   # 6 states, 2 inputs: not the DBC's
    assert firmware_node.main([*node, "--identifier", str(lim), "--dbc", str(exported["dbc"])]) == 2
    assert "--dbc: " in capsys.readouterr().err
    f64 = tmp_path / "f64.toml"
    f64.write_text(exported["config"].read_text().replace('dtype = "float32"', 'dtype = "float64"'))
    assert firmware_node.main([*node, "--identifier", str(f64), "--dbc", str(exported["dbc"])]) == 2
    err = capsys.readouterr().err
    assert "--identifier: " in err and "the firmware runs the float32 core" in err


def test_the_firmware_for_the_identifier_builds_by_hand_as_the_page_shows(exported, tmp_path) -> None:
    # docs/hil-any-identifier.md's commands, run as written from a folder holding the page's files and
    # the firmware sources: the protocol code, the runner and the twin, each in its own folder
    [body] = blocks_by("docs/hil-any-identifier.md",
                       "test_hil_identifier.py::test_the_firmware_for_the_identifier_builds_by_hand_as_the_page_shows")
    if shutil.which("cc") is None:
        pytest.skip("no C compiler")
    for name in ("cfg.toml", "id.dbc"):
        shutil.copy(exported["dir"] / name, tmp_path / name)
    (tmp_path / "firmware_sim").symlink_to(FW, target_is_directory=True)
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    for line in commands(body):
        argv = shlex.split(line)
        proc = subprocess.run([sys.executable, *argv[1:]], capture_output=True, text=True, timeout=900,
                              cwd=str(tmp_path), env=env)
        assert proc.returncode == 0, f"`{line}`: {proc.stderr}{proc.stdout[-2000:]}"
    assert (tmp_path / "build" / "id-protocol" / "rhonn_id_layout.h").exists()
    assert (tmp_path / "build" / "id-runner" / "rhonn_runner").exists()
    assert any((tmp_path / "build" / "id-twin").iterdir())


@pytest.mark.skipif(any(shutil.which(t) is None for t in ("arm-none-eabi-gcc", "qemu-system-arm", "cmake"))
                    and os.environ.get("PYRHONN_REQUIRE_CORTEX_M4") != "1", reason="Cortex-M4 toolchain missing")
def test_the_cortex_m4_image_of_the_identifier_sends_exactly_the_twins_frames(exported, tmp_path) -> None:
    # docs/hil-any-identifier.md's command, run as written on the page's file names (the fixture's), its
    # report written to a JSON file as well
    [body] = blocks_by("docs/hil-any-identifier.md",
                       "test_hil_identifier.py::test_the_cortex_m4_image_of_the_identifier_sends_exactly_the_twins_frames")
    [line] = commands(body)
    argv = shlex.split(line)
    assert argv[:2] == ["python", "firmware_sim/cortex_m4/run_m4.py"], line
    for name in ("cfg.toml", "id.dbc", "data.csv"):
        shutil.copy(exported["dir"] / name, tmp_path / name)
    frames = int(argv[argv.index("--frames") + 1])
    proc = subprocess.run([sys.executable, str(ROOT / argv[1]), *argv[2:], "--json", str(tmp_path / "m4.json")],
                          capture_output=True, text=True, timeout=900, cwd=str(tmp_path))
    assert proc.returncode == 0, proc.stderr + proc.stdout[-2000:]
    report = json.loads((tmp_path / "m4.json").read_text())
    app = report["application"]
    assert app["identical_to_host"] and app["lines_compared"] > 2 * frames
    assert app["status_counts"] == {"FW_OK": frames, "FW_E_SEQ_REPEAT": 1, "FW_E_SEQ_JUMP": 1}
    assert report["capacities"]["RHONN_MAX_STATES"] == 2 and report["capacities"]["RHONN_MAX_DELAY"] >= 2
    assert app["soft_double_routines"] == []
