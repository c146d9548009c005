"""hil replay / hil score verdicts for CI: a scenario file's thresholds judged
against the run's measured values, the exit code, the JUnit XML and the JSON summary."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

pytest.importorskip("can")
pytest.importorskip("cantools")

from pyrhonn.cli import main as pyrhonn_main  # noqa: E402

from hil import verdicts  # noqa: E402
from hil.rig import read_log  # noqa: E402
from hil.score import score  # noqa: E402
from hil.transport import lim_config  # noqa: E402

# 0.9 .. 1.2 s: the position hold starts at 1.1 s, so there is a dropout to bridge
SCENARIO_TOML = """
[scenario]
duration = 0.3
start = 0.9
input_start = 1.0
seed = 4
frame_loss = 0.01
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> dict:
    """One short virtual replay driven by a scenario file with limits it meets, recorded to a log."""
    d = tmp_path_factory.mktemp("verdicts")
    (d / "ci.toml").write_text(SCENARIO_TOML + """
[thresholds]
lost_frames = 0
rmse = { position = 1.0, velocity = 10.0 }
bridging_ratio = { position = 3.0 }
latency_us = { p99 = 1e9 }
""")
    argv = ["hil", "replay", "--transport", "virtual", "--scenario", str(d / "ci.toml"), "--log", str(d / "run.blf"),
            "--junit", str(d / "junit.xml"), "--summary", str(d / "summary.json"), "--out", str(d / "out")]
    code = pyrhonn_main(argv)
    report = score(read_log(d / "run.blf"), reference=lim_config())
    return {"dir": d, "code": code, "report": report}


def _cases(path: Path) -> dict[str, ET.Element]:
    root = ET.parse(path).getroot()
    assert root.tag == "testsuites"
    suite = root.find("testsuite")
    cases = {tc.get("name"): tc for tc in suite.iter("testcase")}
    assert int(suite.get("tests")) == len(cases)
    assert int(suite.get("failures")) == sum(tc.find("failure") is not None for tc in cases.values())
    return cases


def test_a_run_within_every_threshold_exits_0_with_a_junit_file_of_passing_testcases(recorded) -> None:
    d = recorded["dir"]
    assert recorded["code"] == 0
    cases = _cases(d / "junit.xml")
    for name in ("rmse.position", "rmse.velocity", "bridging_ratio.position", "lost_frames", "latency_us.p99",
                 "frames_accounted", "bit_exact"):
        assert name in cases, name
        assert cases[name].find("failure") is None, name
    # latency is not judged on the virtual bus, and the skip says why
    skipped = cases["latency_us.p99"].find("skipped")
    assert skipped is not None and "virtual" in skipped.get("message")
    summary = json.loads((d / "summary.json").read_text())
    assert summary["passed"] is True and summary["failed"] == []
    by_name = {v["name"]: v for v in summary["verdicts"]}
    assert by_name["rmse.position"]["measured"] == pytest.approx(
        recorded["report"]["identification"]["position"]["rmse"])
    text = (d / "out" / "report.txt").read_text()
    assert "verdicts (" in text and "rmse.position" in text and "<= 1" in text and "skipped" in text


def test_a_threshold_below_the_measured_value_fails_its_testcase_and_exits_1(recorded, capsys) -> None:
    d = recorded["dir"]
    rmse = recorded["report"]["identification"]["position"]["rmse"]
    (d / "tight.toml").write_text(f"[thresholds]\nrmse = {{ position = {rmse / 2!r}, velocity = 10.0 }}\n")
    code = pyrhonn_main(["hil", "score", str(d / "run.blf"), "--scenario", str(d / "tight.toml"),
                         "--junit", str(d / "tight.xml"), "--summary", str(d / "tight.json")])
    assert code == 1
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.strip().startswith("rmse.position"))
    assert "FAIL" in row and f"{rmse:.6g}" in row and f"<= {rmse / 2:.6g}" in row
    cases = _cases(d / "tight.xml")
    failure = cases["rmse.position"].find("failure")
    assert failure is not None and "above the limit" in failure.get("message")
    assert cases["rmse.velocity"].find("failure") is None
    summary = json.loads((d / "tight.json").read_text())
    assert summary["passed"] is False and summary["failed"] == ["rmse.position"]
    # the same limit just above the measured value passes
    (d / "loose.toml").write_text(f"[thresholds]\nrmse = {{ position = {rmse * 1.01!r} }}\n")
    assert pyrhonn_main(["hil", "score", str(d / "run.blf"), "--scenario", str(d / "loose.toml")]) == 0


def test_every_kind_of_threshold_fails_when_set_below_the_run(recorded) -> None:
    r = recorded["report"]
    hold = r["identification"]["position"]["hold"]
    ratio = hold["estimate_rmse_inside"] / hold["frames_rmse_inside"]
    th = verdicts.Thresholds(bridging_ratio={"position": ratio * 0.5}, lost_frames=0, latency_us={"p99": 0.0})
    real = {**r, "transport": "udp_multicast"}   # latency is judged on a real transport
    got = {v.name: v for v in verdicts.evaluate(real, th)}
    assert got["bridging_ratio.position"].status == "fail"
    assert got["bridging_ratio.position"].measured == pytest.approx(ratio)
    assert got["latency_us.p99"].status == "fail"
    assert got["lost_frames"].status == "pass"
    lossy = {**real, "frames": {**r["frames"], "missing": 3}}
    assert {v.name: v for v in verdicts.evaluate(lossy, th)}["lost_frames"].status == "fail"


def test_a_limit_the_run_did_not_measure_fails_instead_of_passing(recorded) -> None:
    r = recorded["report"]
    no_hold = {**r, "identification": {**r["identification"],
                                       "velocity": {**r["identification"]["velocity"], "hold": {"cycles": 0}}}}
    got = verdicts.evaluate(no_hold, verdicts.Thresholds(bridging_ratio={"velocity": 10.0}))
    assert got[0].status == "fail" and got[0].reason.startswith("not measured")


@pytest.mark.parametrize("text, named", [
    ("[thresholds]\nrmse = { torque = 1.0 }\n", "thresholds.rmse.torque"),
    ("[thresholds]\nlatency_us = { p42 = 1.0 }\n", "thresholds.latency_us.p42"),
    ("[thresholds]\nrmse = { position = -1.0 }\n", "thresholds.rmse.position"),
    ("[thresholds]\nlost_frames = 1.5\n", "thresholds.lost_frames"),
    ("[thresholds]\nspeed = 1\n", "thresholds.speed"),
    ("[plots]\n", "[plots]"),
    ("[scenario]\nduration = -1\n", "[scenario].duration"),
    ("[scenario]\nwarp = 9\n", "unknown fields"),
    ("rmse = [", "not valid TOML"),
    ('[scenario]\ntrajectory = "t.csv"\ninput_start = 1.0\n', "[scenario].input_start"),
])
def test_a_bad_scenario_file_is_refused_naming_the_key(tmp_path, cli_error, text, named) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(text)
    (tmp_path / "t.csv").write_text("t,q_m,v,lambda_a,lambda_b,i_a,i_b,u_a,u_b\n")
    assert named in cli_error(["hil", "replay", "--transport", "virtual", "--scenario", str(f)])


def test_the_file_and_the_command_line_may_not_both_set_a_field(recorded, cli_error, tmp_path) -> None:
    f = tmp_path / "s.toml"
    f.write_text(SCENARIO_TOML)
    err = cli_error(["hil", "replay", "--transport", "virtual", "--scenario", str(f), "--seed", "5"])
    assert "seed" in err and "command line" in err
    # hil score: the file's [scenario] must be the log's own
    other = tmp_path / "other.toml"
    other.write_text(SCENARIO_TOML.replace("seed = 4", "seed = 5"))
    assert "seed" in cli_error(["hil", "score", str(recorded["dir"] / "run.blf"), "--scenario", str(other)])
    assert "[scenario]" in cli_error(["hil", "replay", "--transport", "virtual", "--from-log",
                                      str(recorded["dir"] / "run.blf"), "--scenario", str(f)])


def test_the_scenario_table_drives_the_replay(recorded) -> None:
    sc = recorded["report"]["scenario"]
    assert (sc["duration"], sc["start"], sc["input_start"], sc["seed"], sc["frame_loss"]) == (0.3, 0.9, 1.0, 4, 0.01)
