"""The benchmark figures the docs quote come from the results files the benchmarks
write (bench/results/NAME.json, by ``bench/bench_NAME.py --results``): every
``{{ bench("NAME", "a.b.c") }}`` of a page resolves, the built page shows the file's
value, a missing figure fails the build naming it, and no page quotes by hand a
figure it also takes from a results file."""
from __future__ import annotations

import contextlib
import io
import json
import math
import re
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from source_scripts import load_script  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
PAGES = sorted((ROOT / "docs").rglob("*.md"))


@pytest.fixture(scope="module")
def hooks() -> ModuleType:
    pytest.importorskip("mkdocs")
    return load_script(ROOT / "docs_hooks.py", "docs_hooks")


def _references(hooks: ModuleType) -> list[tuple[Path, str, str, str | None, bool]]:
    """(page, results name, path, format spec, from the run's record) of every reference."""
    return [(page, m.group(2), m.group(3), m.group(4), bool(m.group(1))) for page in PAGES
            for m in hooks.BENCH_REF.finditer(page.read_text(encoding="utf-8"))]


def test_the_docs_quote_benchmark_figures_through_references(hooks: ModuleType) -> None:
    names = {name for _, name, _, _, _ in _references(hooks)}
    assert {"cortex_m4", "core_vs_dense", "real_data", "identifier", "xcp", "structure", "population", "writes",
            "wide", "linux_runner", "soak", "hil_udp", "recordings",
            "tune_validation", "reproduce", "tune_search"} <= names


def test_every_figure_reference_in_the_docs_resolves_against_bench_results(hooks: ModuleType) -> None:
    unresolved = []
    for page, name, path, spec, run in _references(hooks):
        try:
            hooks.bench_figure(name, path, spec, run=run)
        except ValueError as exc:
            unresolved.append(f"{page.relative_to(ROOT)}: {exc}")
    assert not unresolved, "\n".join(unresolved)


def test_a_reference_that_looks_like_one_but_does_not_parse_is_left_for_the_build_to_refuse(hooks: ModuleType) -> None:
    # a malformed reference (single quotes) is not replaced, so on_page_markdown's leftover check refuses it
    text = "{{ bench('cortex_m4', 'unrolled.instructions_per_step') }}"
    assert hooks.render_bench(text) == text
    assert re.findall(r"\{\{ bench\(.*?\}\}", text)


def _set(record: Any, path: str, k: int) -> int | str:
    """Replace the figure at ``path`` (keys and list indices joined by dots) by a marker of the
    same kind (a number, or a 10-character text for a text such as a date); the marker."""
    *parents, last = path.split(".")
    for part in parents:
        record = record[int(part)] if isinstance(record, list) else record[part]
    key: Any = int(last) if isinstance(record, list) else last
    marker: int | str = f"marker{k:04d}" if isinstance(record[key], str) else 900_001 + k
    record[key] = marker
    return marker


def test_the_built_page_shows_the_results_file_value(hooks: ModuleType, tmp_path: Path) -> None:
    """Change every figure a page references in a copy of the results: the page follows the copy."""
    committed = {file.stem: file.read_text(encoding="utf-8") for file in RESULTS.glob("*.json")}
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        refs = list(hooks.BENCH_REF.finditer(text))
        if not refs:
            continue
        marked: dict[tuple[str, str, str], int | str] = {}  # each figure referenced gets a value of its own
        copies: dict[str, Any] = {}  # the committed figures, marked for this page (the page reads only these)
        for m in refs:
            key = (m.group(1) or "", m.group(2), m.group(3))
            if key in marked:
                continue
            data = copies.setdefault(m.group(2), json.loads(committed[m.group(2)]))
            marked[key] = _set(data if m.group(1) else data["figures"], m.group(3), len(marked))
        for name, data in copies.items():
            (tmp_path / f"{name}.json").write_text(json.dumps(data), encoding="utf-8")
        hooks._RESULTS_CACHE.clear()
        shown = hooks.render_bench(text, tmp_path)
        assert "{{ bench" not in shown
        for m in refs:
            expected = hooks.format_figure(marked[(m.group(1) or "", m.group(2), m.group(3))], m.group(4))
            assert expected in shown, f"{page.name}: {m.group(0)} does not show {expected}"
    hooks._RESULTS_CACHE.clear()


def test_a_missing_figure_or_results_file_fails_naming_it(hooks: ModuleType, tmp_path: Path) -> None:
    (tmp_path / "demo.json").write_text(json.dumps({"figures": {"step": {"cycles": 4901}}}), encoding="utf-8")
    assert hooks.render_bench('{{ bench("demo", "step.cycles") }} cycles', tmp_path) == "4,901 cycles"
    (tmp_path / "run.json").write_text(json.dumps({"figures": {"x": 1}, "load": {"start": [9.5, 8, 7]}}),
                                       encoding="utf-8")
    assert hooks.render_bench('at load {{ bench_run("run", "load.start.0", ".1f") }}', tmp_path) == "at load 9.5"
    with pytest.raises(ValueError, match=r"demo\.json: no figure 'step\.median' \(no 'median'\)"):
        hooks.render_bench('{{ bench("demo", "step.median") }}', tmp_path)
    with pytest.raises(ValueError, match=r"bench/results/absent\.json: no such results file"):
        hooks.render_bench('{{ bench("absent", "x") }}', tmp_path)
    with pytest.raises(ValueError, match=r"figure 'step': not a number or text"):
        hooks.render_bench('{{ bench("demo", "step") }}', tmp_path)


def test_figures_are_formatted_as_the_pages_write_them(hooks: ModuleType) -> None:
    assert hooks.format_figure(4463, None) == "4,463"
    assert hooks.format_figure(6672.4, None) == "6,672"
    assert hooks.format_figure(3.7512, None) == "3.75"
    assert hooks.format_figure(0.08855, ".1%") == "8.9 %"
    assert hooks.format_figure(4.8e-12, ".1e") == "4.8e-12"
    assert hooks.format_figure(1.7e-5, ".2e") == "1.70e-5"
    assert hooks.format_figure(1030.4, "/1e3:.2f") == "1.03"
    with pytest.raises(ValueError, match="scaled format"):
        hooks.format_figure(1030.4, "/1e3")
    assert hooks.format_figure(True, None) == "yes"


def _digits(text: str) -> int:
    """Significant digits of a figure as shown (``4,906``: 4; ``0.041``: 2; ``1.3e+03``: 2)."""
    mantissa = re.split(r"[eE]", text)[0].lstrip("-0.,")
    return sum(c.isdigit() for c in mantissa)


#: literals of a page that equal a figure of the last run by chance, with what they are
COINCIDENCES = {
    ("docs/benchmarks.md", "1,113"),  # the core's operation count at L = 16 (counted, not measured)
    ("docs/robustness.md", "20,000"),  # the steps of a tested run of the U D U^T form, not a bench setting
    # the paper's own table entries, read in the prose (facts of the paper, not of a run)
    ("docs/reproduction.md", "0.36338"),  # Tables 1-2: x4's RMSE and AD, printed equal
    ("docs/reproduction.md", "8.7961e-6"),  # Table 6: the position's AD
    ("docs/reproduction.md", "4.4238e-5"),  # Table 6: the velocity's AD
}


def test_no_page_quotes_by_hand_a_figure_the_docs_take_from_a_results_file(hooks: ModuleType) -> None:
    """A figure with 4 digits or more that any page takes from a results file does not also stand
    in a page as a literal: a hand copy (or a reference replaced by its value) would go stale
    when the benchmark is rerun."""
    shown = {hooks.bench_figure(name, path, spec, run=run): f"{name}: {path}"
             for _, name, path, spec, run in _references(hooks)}
    literals = [(re.compile(rf"(?<![\d.,]){re.escape(text)}(?![\d]|,\d)"), text, what)
                for text, what in shown.items() if _digits(text) >= 4]
    copies = []
    for page in PAGES:
        bare = hooks.BENCH_REF.sub(" ", page.read_text(encoding="utf-8"))
        for literal, text, what in literals:
            if (page.relative_to(ROOT).as_posix(), text) in COINCIDENCES:
                continue
            if text in bare and literal.search(bare):  # the plain test first: most figures stand nowhere
                copies.append(f"{page.relative_to(ROOT)}: {text} ({what}) written by hand")
    assert not copies, "\n".join(sorted(copies))


def test_every_results_file_says_when_where_under_what_load_and_how_it_ran() -> None:
    files = sorted(RESULTS.glob("*.json"))
    assert files
    for file in files:
        data = json.loads(file.read_text(encoding="utf-8"))
        assert data["bench"] == file.stem
        assert re.match(r"\d{4}-\d\d-\d\dT", data["date"])
        assert data["machine"]["cpu"] and data["machine"]["nproc"] >= 1
        assert len(data["load"]["start"]) == 3 and len(data["load"]["end"]) == 3
        assert data["command"].startswith(f"python bench/bench_{file.stem}.py")
        assert isinstance(data["figures"], dict) and data["figures"]


def test_results_writer_replaces_the_file_whole_and_refuses_bad_figures(tmp_path: Path) -> None:
    writer = load_script(ROOT / "bench" / "results_file.py", "results_file")
    path = writer.save("demo", {"step": {"cycles": 4901}}, ["--frames", "20"], folder=tmp_path)
    data = json.loads(path.read_text(encoding="utf-8"))
    assert data["figures"] == {"step": {"cycles": 4901}} and data["bench"] == "demo"
    assert data["command"].endswith("--frames 20") and data["machine"]["nproc"] >= 1
    # a scratch folder of the machine that ran it is not recorded
    path = writer.save("demo", {"x": 1}, ["--huge-dir", str(tmp_path), f"--out={tmp_path}"], folder=tmp_path)
    assert json.loads(path.read_text(encoding="utf-8"))["command"] == "python bench/bench_demo.py --huge-dir DIR --out=DIR"
    before = path.read_bytes()
    with pytest.raises(TypeError):  # not a JSON value: refused, the previous file kept
        writer.save("demo", {"step": object()}, [], folder=tmp_path)
    with pytest.raises(ValueError, match="name"):
        writer.save("../demo", {"x": 1}, [], folder=tmp_path)
    with pytest.raises(ValueError, match="figures"):
        writer.save("demo", {}, [], folder=tmp_path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.json"]
    writer.save("demo", {"free_run": [math.inf, math.nan, 0.5]}, [], folder=tmp_path)  # a diverged run
    assert json.loads(path.read_text(encoding="utf-8"))["figures"] == {"free_run": ["inf", "nan", 0.5]}


def test_bench_commands_of_the_docs_write_the_results_files_they_name() -> None:
    # each script of docs/contributing-docs.md's list takes --results and writes the file the line
    # names (results_file.save with that name), and that file is committed; the runs themselves take
    # minutes to an hour, so they are not repeated here
    from docs_blocks import blocks_by, commands

    lines = [line for body in blocks_by("docs/contributing-docs.md",
                                        "test_bench_figures.py::test_bench_commands_of_the_docs_write_the_results_files_they_name")
             for line in commands(body)]
    assert len(lines) >= 7
    for line in lines:
        m = re.fullmatch(r"python (bench/bench_(\w+)\.py)(?: [^#]*)? --results(?: [^#]*)?\s*# (bench/results/(\w+)\.json)", line)
        assert m, f"docs/contributing-docs.md: `{line}` is not `python bench/bench_NAME.py ... --results  # bench/results/NAME.json`"
        script, name, results, named = m.groups()
        assert name == named, line
        source = (ROOT / script).read_text(encoding="utf-8")
        assert '"--results"' in source and re.search(rf'save\(\s*"{name}"', source), f"{script} does not write {results}"
        assert (ROOT / results).exists(), f"{results} is not committed"
        assert json.loads((ROOT / results).read_text(encoding="utf-8"))["bench"] == name


#: a time, a cycle count or a size as a page writes it: ``263 ns``, ``0.86-0.87 µs``, ``4,600 cycles``, ``30.6 kB``
MEASURED_LOOKING = re.compile(r"(?<![\w.])\d[\d,]*(?:\.\d+)?(?:\s?(?:-|–|->|to)\s?\d[\d,]*(?:\.\d+)?)?"
                              r"\s?(?:ns|µs|us|ms|cycles|MiB|KiB|kB|KB|MB|GB)\b")

_NUMBER = r"\d[\d,]*(?:\.\d+)?"
#: a run time, a share or a ratio as a page writes it: ``11.3 s``, ``6.7-11.3 s``, ``2s``, ``71%``, ``1.6 %``,
#: ``1.29x``, ``0.93x-0.96x``, ``2.3-2.5x``, ``2.4x -> 2.5x``
RUN_LOOKING = re.compile(rf"(?<![\w.])(?<!e-){_NUMBER}(?:\s?(?:-|–|to)\s?{_NUMBER})?\s?(?:s|%)(?![\w%])"
                         rf"|(?<![\w.])(?<!e-){_NUMBER}x?(?:\s?(?:-|–|->)\s?{_NUMBER})?x(?!\w)")

#: figures of those looks which are specifications wherever they stand, with what they are
SPECIFIED_EVERYWHERE = {
    "0.3 ms": "the rig's period, the protocol's cycle and the firmware's budget",
    "0.1 ms": "the LIM simulation's sampling period",
    "0.2 s": "Example 1's first sampling period (the paper's)",
    "0.02 s": "Example 1's second sampling period (the paper's)",
    "100 s": "Example 1's default horizon (the oscillator's)",
}
_FENCED = re.compile(r"^```.*?^```", re.S | re.M)

#: figures of that look which are not measurements, with what they are; each must still stand on its page
SPECIFIED = {
    ("docs/firmware-protocol.md", "10 ns"): "StepTimeMax's resolution (the DBC's scale)",
    ("docs/firmware-protocol.md", "167,772.15 µs"): "the top of StepTimeMax's 24 bits of 10 ns",
    ("docs/firmware-protocol.md", "655.35 µs"): "the top of StepTime's and CycleTime's 16 bits of 10 ns",
    ("docs/firmware-sim.md", "149 us"): "the runner's spin, the most the 0.3 ms period allows (an option's value)",
    ("docs/firmware-sim.md", "50 us"): "the runner's spin `hil replay` sets",
    ("docs/firmware-sim.md", "4 MiB"): "the default receive buffer the node asks for",
    ("docs/firmware-sim.md", "1 µs"): "the simulated clock's advance per read, set by the memory HAL",
    ("docs/firmware-sim.md", "50,400 cycles"): "the budget: 0.3 ms at 168 MHz",
    ("docs/firmware.md", "14 cycles"): "VDIV's latency in the Cortex-M4 timing tables",
    ("docs/firmware.md", "5,000 cycles"): "the cycles aimed at for the step (a target)",
    ("docs/hil-any-identifier.md", "300 cycles"): "the length of the VM test's run",
    ("docs/hil-replay.md", "50 us"): "the runner's spin `hil replay` sets",
    ("docs/hil-replay.md", "149 us"): "the runner's spin `hil bench` sets on two or more CPUs",
    ("docs/hil-replay.md", "10 ns"): "StepTimeMax's resolution",
    ("docs/hil-replay.md", "167,772.15 us"): "the top of StepTimeMax's 24 bits",
    ("docs/hil-replay.md", "167,772.1 us"): "the report's line for a saturated StepTimeMax",
    ("docs/hil-replay.md", "655.35 us"): "the top of the 16-bit StepTime",
    ("docs/hil-replay.md", "100 cycles"): "how long the test stops the firmware process",
    ("docs/hil-replay.md", "32 MiB"): "the receive buffer the rig and the node ask for",
    ("docs/hil-replay.md", "13333 cycles"): "the progress line's form, for the LIM scenario's length",
    ("docs/hil-replay.md", "256 cycles"): "how often the rig offers its counts",
    ("docs/hil-verdicts.md", "850.8 us"): "the failure message of the example report shown above it",
    ("docs/hil-verdicts.md", "512 cycles"): "how often `hil replay` reads the kernel's drop counters",
    ("docs/recordings.md", "64 MiB"): "the largest uncompressed object a file may declare",
    ("docs/recordings.md", "4 MiB"): "the block a CSV file is read in",
    ("docs/status.md", "1 µs"): "the call overhead aimed at (a target)",
    ("docs/xcp.md", "5,000 cycles"): "the cycles aimed at for the step (a target)",
    ("docs/hil-replay.md", "10 ms"): "the tick of /proc/stat's CPU times",
    ("docs/contributing-docs.md", "263 ns"): "an example of what the check refuses",
    ("docs/contributing-docs.md", "0.86-0.87 µs"): "an example of what the check refuses",
    ("docs/contributing-docs.md", "4,600 cycles"): "an example of what the check refuses",
    ("docs/contributing-docs.md", "30.6 kB"): "an example of what the check refuses",
    ("docs/hil-verdicts.md", "154 ms"): "512 cycles of 0.3 ms",
    ("docs/plants.md", "5 ms"): "the oscillator solver's internal step (`DEFAULT_STEP`)",
    ("docs/plants.md", "2.5 ms"): "half that step, of the convergence check",
    ("docs/plants.md", "19.2 ms"): "the LIM's armature time constant L_a / R_a, from its parameters",
    ("docs/plants.md", "0.67 ms"): "a time constant of the LIM model, from its parameters",
    ("docs/reproduction.md", "5 ms"): "the oscillator solver's internal step",
    ("docs/xcp.md", "1 us"): "the DAQ timestamp's unit",
    **{("docs/contributing-docs.md", f): "an example of what the check refuses" for f in ("11.3 s", "71%", "1.29x")},
    # run times, shares and ratios that are specifications, settings, targets or examples
    ("docs/benchmarks.md", "10 %"): "the error beyond which the page marks `rhonn_wide_pays`'s advice",
    ("docs/benchmarks.md", "2.0 s"): "where the LIM samples the bench times start (the voltages switch on)",
    ("docs/benchmarks.md", "5x"): "the speed-up aimed at (a target)",
    ("docs/benchmarks.md", "1.98x"): "the operation counts 417 / 211 at L = 5 (counted from the formulas, not measured)",
    ("docs/benchmarks.md", "2.52x"): "the operation counts 662 / 263 at L = 6 (counted from the formulas, not measured)",
    ("docs/benchmarks.md", "99.9 %"): "the share of estimates aimed at within one period (a target)",
    ("docs/benchmarks.md", "1 s"): "the paper's position hold",
    ("docs/benchmarks.md", "3x"): "the population throughput aimed at (a target)",
    ("docs/can-log.md", "1 s"): "the scenario's position hold",
    ("docs/firmware-protocol.md", "6 s"): "the simulated LIM example's length",
    ("docs/firmware-protocol.md", "9.8 s"): "32767 frames of 0.3 ms",
    ("docs/firmware-sim.md", "2.0 s"): "when the simulated LIM's voltages switch on",
    ("docs/firmware-sim.md", "15 %"): "the Measurement frame's share of the budget aimed at (a target)",
    ("docs/firmware.md", "1 s"): "when the example identifier is exported, after the motor starts",
    ("docs/firmware.md", "15 %"): "the Measurement frame's share of the budget aimed at (a target)",
    ("docs/hil-replay.md", "2 s"): "the paper's timing: the voltages switch on",
    ("docs/hil-replay.md", "1.1-2.1 s"): "the paper's timing: the position hold",
    ("docs/hil-replay.md", "2.0 s"): "the paper's timing: the motor starts",
    ("docs/hil-replay.md", "0.3 s"): "`--drain`'s default",
    ("docs/hil-replay.md", "0.5 s"): "the hold the shipped `firmware-lim` was designed on",
    ("docs/hil-replay.md", "46 %"): "the progress line's form (6144 of 13333 cycles)",
    ("docs/hil-replay.md", "10 s"): "a replay's length, for the size of its log",
    ("docs/hil-replay.md", "99.9 %"): "the share of estimates aimed at within one period (a target)",
    ("docs/hil-verdicts.md", "15x"): "an example of a run the default checks do not judge",
    ("docs/hil-verdicts.md", "95 %"): "the chi-square band the health figure draws",
    ("docs/own-data.md", "1.2 s"): "the length of the example file",
    ("docs/own-data.md", "0.6 s"): "a sample of the example file marked not updated",
    ("docs/own-data.md", "0.8 s"): "a sample of the example file marked not updated",
    ("docs/python-api.md", "4 s"): "the replay whose log the bench writes",
    ("docs/real-data.md", "4 s"): "the cascaded tanks' sampling period",
    ("docs/reproduce.md", "10 s"): "the horizon before x4's first spike (a horizon of the study)",
    ("docs/reproduce.md", "150 s"): "the longest horizon of the study",
    ("docs/reproduce.md", "1 s"): "the LIM scenario's position hold",
    ("docs/reproduce.md", "2.1 s"): "when the LIM scenario's position hold starts",
    ("docs/robustness.md", "30 s"): "how long `make test-fuzz` runs a target",
    ("docs/robustness.md", "20 s"): "how long `make test-fuzz` runs a target",
    ("docs/robustness.md", "99.7 %"): "the chi-square quantile the gate's default 9 stands for",
    ("docs/selection-and-tuning.md", "10 %"): "the residual cut a tap must bring to be kept (the search's rule)",
    ("docs/selection-and-tuning.md", "5 %"): "the free-run tie the search allows (its rule)",
    ("docs/selection-and-tuning.md", "99 %"): "the whiteness tests' bounds",
    ("docs/selection-and-tuning.md", "70%"): "the estimation share of the comparison's split",
    ("docs/selection-and-tuning.md", "30%"): "the validation share of the comparison's split",
    ("docs/selection-and-tuning.md", "15 s"): "the robot scenario's horizon",
    ("docs/selection-and-tuning.md", "2-4 s"): "the LIM window the comparison uses",
    ("docs/selection-and-tuning.md", "30 s"): "the held-out window of Example 1",
    ("docs/selection-and-tuning.md", "3 s"): "the oscillator's delay tau",
    ("docs/selection-and-tuning.md", "10 s"): "the search's run time aimed at (a target)",
    ("docs/selection-and-tuning.md", "1 %"): "a --tie width the real-data benchmark runs (a setting)",
    ("docs/selection-and-tuning.md", "2 %"): "a --tie width the real-data benchmark runs (a setting)",
    ("docs/robustness.md", "95 %"): "the carried share of proofs a test holds at least (a bound)",
    ("docs/status.md", "2x"): "the target for Examples 2-3",
    ("docs/status.md", "0.5 s"): "the HIL scenario's position hold",
    ("docs/status.md", "15 %"): "the Measurement frame's share of the budget aimed at (a target)",
    ("docs/status.md", "3x"): "the population throughput aimed at (a target)",
    ("docs/status.md", "0.3 s"): "how long into the hold `example3`'s float32 prediction lasts, by its sample number",
    ("docs/status.md", "0.4 s"): "how long into the hold `example3`'s float64 prediction lasts, by its sample number",
    ("docs/status.md", "99.9 %"): "the share of estimates aimed at within one period (a target)",
    ("docs/status.md", "1 s"): "Table 7's position hold",
    ("docs/xcp.md", "0x"): "the hex prefix",
    ("docs/xcp.md", "15 %"): "the Measurement frame's share of the budget aimed at (a target)",
    # the paper's plants: parameters, inputs, horizons, holds, and the models' own properties
    **{("docs/plants.md", f): "a parameter, input, horizon or hold of the paper's plants or their scenarios"
       for f in ("2.1 s", "4 s", "0.1 s", "0.01 s", "3 s", "20 s", "20.9 s", "150 s", "3.2 s", "15 s", "5 s", "2 s",
                 "1 s", "1.1 s", "2.0 s", "0 s")},
    ("docs/plants.md", "80 %"): "the share of Example 1's samples after its start-up (20 of 100 s)",
    ("docs/plants.md", "0.05 %"): "the robot model's agreement with the reference model, a bound its tests check",
    ("docs/plants.md", "2 %"): "the robot model's agreement with the reference model, a bound its tests check",
    ("docs/plants.md", "25 %"): "the robot's forward-Euler error at the start, a property of the model",
    ("docs/plants.md", "1.4 %"): "the robot's forward-Euler error over the run, a property of the model",
    ("docs/plants.md", "1 %"): "the LIM's step-halving bound a test checks",
    **{("docs/reproduction.md", f): "a sampling period, horizon, hold, delay or input time of the paper's scenarios"
       for f in ("5 s", "0.01 s", "15 s", "10 s", "150 s", "20 s", "50 s", "0-50 s", "50-100 s", "100-150 s",
                 "3 s", "100-200 s", "0.1 s", "1 s", "2.1-3.1 s", "2 s", "2s", "10.4 s", "11 s")},
    ("docs/reproduction.md", "2x"): "the target for Examples 2-3",
}


def hand_written_figures(text: str) -> list[str]:
    """The measured-looking figures (times, cycles, sizes, run times, shares, ratios) of a page's
    text outside its ``{{ ... }}`` references and its fenced blocks (commands and the output they
    print, which the docs tests run or show as is), in the order they stand."""
    prose = _FENCED.sub("", re.sub(r"\{\{.*?\}\}", " ", text, flags=re.S))
    found = sorted([*MEASURED_LOOKING.finditer(prose), *RUN_LOOKING.finditer(prose)], key=lambda m: m.start())
    return [re.sub(r"\s+", " ", m.group(0)) for m in found]


def _pages_and_readme() -> list[Path]:
    return [*PAGES, ROOT / "README.md"]


def unlisted_figures(name: str, text: str) -> list[str]:
    """The hand-written figures of page ``name`` (its ``text``) that SPECIFIED does not list."""
    return [f"{name}: {figure!r} is written by hand (quote it from bench/results, say it in words, or add it "
            "to SPECIFIED with what it is if it is a specification)"
            for figure in hand_written_figures(text)
            if (name, figure) not in SPECIFIED and figure not in SPECIFIED_EVERYWHERE]


def test_no_page_writes_a_measured_figure_by_hand() -> None:
    """A time, cycle count, size, run time, share or ratio a benchmark measures is quoted through
    ``bench(...)`` (or said in words): one written as a number goes stale when the benchmark is
    rerun. History belongs to the changelog. Only the specifications of SPECIFIED may stand as numbers."""
    found = [line for page in _pages_and_readme()
             for line in unlisted_figures(page.relative_to(ROOT).as_posix(), page.read_text(encoding="utf-8"))]
    assert not found, "\n".join(found)


def test_a_run_time_share_or_ratio_planted_in_a_page_is_refused() -> None:
    name = "docs/reproduction.md"
    page = (ROOT / name).read_text(encoding="utf-8")
    assert unlisted_figures(name, page) == []
    planted = page + "\nIt took 11.3 s (6.7-11.3 s before); x4 is at 1.29x, AD 0.93x-0.96x, 2.7-2.9x; 72% of it.\n"
    found = unlisted_figures(name, planted)
    assert [re.search(r"'(.*)'", line).group(1) for line in found] == [  # type: ignore[union-attr]
        "11.3 s", "6.7-11.3 s", "1.29x", "0.93x-0.96x", "2.7-2.9x", "72%"]
    # the same figures through a reference, or a specification of the page, pass
    assert unlisted_figures(name, page + '\nIt took {{ bench("reproduce", "run.wall_seconds", ".1f") }} s at T = 0.2 s.\n') == []


def test_every_specified_figure_still_stands_on_its_page() -> None:
    # an entry whose figure left its page is removed, so the list cannot excuse a figure written later
    texts = {p.relative_to(ROOT).as_posix(): set(hand_written_figures(p.read_text(encoding="utf-8")))
             for p in _pages_and_readme()}
    stale = [f"{page}: {figure}" for page, figure in SPECIFIED if figure not in texts.get(page, set())]
    assert not stale, "\n".join(stale)


def test_the_figure_check_finds_times_cycles_and_sizes_but_not_references_or_blocks() -> None:
    text = ("The step took 263 ns, then 0.86-0.87 µs; 4,600 cycles and 30.6 kB of flash,\n2,136 cycles,"
            " 12 MiB, 8.1 ms, 44 KB. {{ bench(\"identifier\", \"lim.float64.batched_ns\", \".0f\") }} ns and x0 are not.\n"
            "```text\nstep max 208.4 us\n```\n")
    assert hand_written_figures(text) == ["263 ns", "0.86-0.87 µs", "4,600 cycles", "30.6 kB", "2,136 cycles",
                                          "12 MiB", "8.1 ms", "44 KB"]


def test_the_figure_check_finds_run_times_shares_and_ratios_but_not_words_or_names() -> None:
    text = ("It took 11.3 s (6.7-11.3 s, 7.5s); 71% and 1.6 % of it; RMSE 1.29x, 0.93x-0.96x, 2.3-2.5x,"
            " 2.4x -> 2.5x.\nNot 10 samples, 3 states, x4, 0x20, 2 x 3000 trials, 1e-4 s... nor {{ bench(\"a\", \"b\") }}x.\n"
            "```text\ndone in 11.3 s\n```\n")
    assert hand_written_figures(text) == ["11.3 s", "6.7-11.3 s", "7.5s", "71%", "1.6 %", "1.29x", "0.93x-0.96x",
                                          "2.3-2.5x", "2.4x -> 2.5x"]


def test_the_sizes_the_pages_quote_are_the_builds_pyrhonn_info_reports(hooks: ModuleType) -> None:
    """Every ``{{ NAME }}`` size of a page is measured when the site is built; the package's own
    builds' sizes are those ``pyrhonn info`` reports, not a copy that goes stale with a capacity."""
    from pyrhonn.cli import main

    sizes = hooks._package_sizes()
    info = io.StringIO()
    with contextlib.redirect_stdout(info):
        assert main(["info", "--json"]) == 0
    for build in json.loads(info.getvalue())["builds"]:
        size = "small" if "_small_" in build["module"] else "large"
        assert sizes[f"lanes_workspace.{size}.{build['dtype']}.kB"] == f"{build['sizeof_population_work'] / 1e3:.0f}"
        assert sizes[f"sizeof_rhonn_t.{size}.{build['dtype']}.MB"] == f"{build['sizeof_rhonn_t'] / 1e6:.1f}"
    quoted = {m.group(1) for page in PAGES for m in re.finditer(r"\{\{ ([\w.]+) \}\}", page.read_text(encoding="utf-8"))}
    assert quoted - set(hooks._measured()) == set()
    assert "lanes_workspace.small.float64.kB" in quoted and "sizeof_rhonn_t.large.float64.MB" in quoted


def check_verdicts(figures: dict[str, Any]) -> None:
    """AssertionError unless every verdict of the reproduce results follows from its figures."""
    from pyrhonn.reproduce import AD_TARGET, RMSE_TARGET

    def within(state: dict[str, Any], example: str) -> bool:
        return all(r is None or limit is None or r <= limit for r, limit in
                   ((state.get("rmse_ratio"), RMSE_TARGET.get(example)), (state.get("ad_ratio"), AD_TARGET.get(example))))

    judged = 0
    for key, scenario in figures.items():
        if not key.startswith("example") or "_" in key.split("-")[0]:
            continue  # not a scenario of the command's run
        example = key.split("-")[0]
        for est, states in scenario.items():
            if est == "horizons":
                for at in states.values():
                    for name, point in at.items():
                        if "missed" in point:
                            missed = [f"x{j + 1}" for j, (r, a) in enumerate(zip(point["rmse_ratio"], point["ad_ratio"]))
                                      if not within({"rmse_ratio": r, "ad_ratio": a}, example)]
                            assert point["missed"] == (", ".join(missed) or "none"), (key, name)
                            judged += 1
                continue
            for name, state in states.items():
                if "verdict" in state:
                    assert state["verdict"] == ("met" if within(state, example) else "not met"), (key, est, name)
                    judged += 1
    targets = figures["targets"]
    for span, limit in ((targets["example2_rmse"], RMSE_TARGET["example2"]),
                        (targets["example3_rmse"], RMSE_TARGET["example3"]),
                        *((targets["example1_dt0_02_ad"][est], AD_TARGET["example1"]) for est in ("identifier", "identifier-tuned"))):
        assert span["min"] <= span["max"]
        assert (span["verdict"] == "met on every state") == (span["max"] <= limit)
        judged += 1
    for est, at10 in targets["example1_dt0_2_at_10s"].items():
        top = max(at10["rmse_ratio"]["max"], at10["ad_ratio"]["max"])
        assert (at10["verdict"] == "met on every state") == (top <= RMSE_TARGET["example1"]), est
    run = figures["run"]
    assert run["verdict"] == ("met" if run["wall_seconds"] <= run["target_seconds"] else "not met")
    assert run["computation_seconds"] <= run["seconds"] <= run["wall_seconds"]
    assert judged >= 40


def test_every_verdict_of_the_reproduce_results_agrees_with_the_figures_it_judges() -> None:
    """The pages quote "met" / "not met" from bench/results/reproduce.json beside the ratios: each
    verdict there follows from those ratios and pyrhonn's targets, so no page shows a verdict its
    figures contradict; a verdict changed by hand is caught."""
    figures = json.loads((RESULTS / "reproduce.json").read_text(encoding="utf-8"))["figures"]
    check_verdicts(figures)
    for change in ({"example1-dt0_2": {"identifier": {"x2": {"verdict": "met"}}}},
                   {"example1-dt0_2": {"horizons": {"h50": {"identifier": {"missed": "x2"}}}}},
                   {"targets": {"example2_rmse": {"verdict": "not met on 1 of 7 states"}}},
                   {"run": {"wall_seconds": 130.0}}):
        edited = json.loads(json.dumps(figures))
        (key, inner), = change.items()
        node = edited[key]
        while True:
            (k, v), = inner.items()
            if not isinstance(v, dict):
                node[k] = v
                break
            node, inner = node[k], v
        with pytest.raises(AssertionError):
            check_verdicts(edited)
