"""MkDocs hooks: the reference pages generated from the code at build time.

``mkdocs build`` (see ``mkdocs.yml``) calls :func:`on_files`, which adds pages
that are never written by hand, so they cannot go stale:

- ``reference/cli.md``: every ``pyrhonn`` command and option, walked from the
  argparse parser the command line itself builds (``hil`` included, through
  its entry point);
- ``reference/config.md``: the config file format from :mod:`pyrhonn.configfile`
  (its documented example and rules) and the keys it accepts;
- ``reference/c-api.md``: every declaration of the C headers with the comment
  above it, then each header whole;
- ``hil/docs/*.png``: the HIL report's figures that ``docs/hil-replay.md`` shows;
- ``changelog.md`` from ``CHANGELOG.md``, when there is one.

:func:`on_config` adds the pages of :data:`OPTIONAL_PAGES` to the navigation
once they exist.

:func:`on_page_content` shows the docstrings' reST roles as plain code, and
:func:`on_page_markdown` replaces each ``{{ NAME }}`` of a page with a figure
measured as the site is built (:func:`_measured`: ``sizeof(rhonn_t)`` for the
capacities the pages discuss, and the sizes of the package's own builds that
``pyrhonn info`` reports), so no page quotes a stale size, and each
``{{ bench("NAME", "a.b.c") }}`` with the figure ``a.b.c`` of the results file
``bench/results/NAME.json`` that ``bench/bench_NAME.py --results`` writes
(:func:`bench_figure`), so no page quotes a stale benchmark figure. A missing
file or figure fails the build, naming both.
"""
from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parent
HEADERS = ("rhonn.h", "rhonn_capacity.h", "rhonn_warm.h", "rhonn_population.h")


def _cli_page() -> str:
    from pyrhonn.cli import build_parser

    out = ["# Command line reference", "",
           "Generated from the `pyrhonn` argument parser when the site is built: every command, "
           "every option, with its help text. `pyrhonn COMMAND --help` prints the same.", ""]

    def walk(parser: argparse.ArgumentParser, path: list[str], level: int, summary: str | None) -> None:
        sub = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        helps = {c.dest: c.help for a in sub for c in a._choices_actions}
        if path:
            out.extend([f"{'#' * level} `{' '.join(path)}`", ""])
            if summary:
                out.extend([summary[0].upper() + summary[1:] + ".", ""])
        out.extend(["```text", parser.format_help().rstrip(), "```", ""])
        for action in sub:
            for name, child in action.choices.items():
                walk(child, [*path, name] if path else ["pyrhonn", name], min(level + 1, 4), helps.get(name))

    import os

    width = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "80"  # argparse wraps to the terminal: the page must not depend on it
    try:
        walk(build_parser(), [], 1, None)
    finally:
        if width is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = width
    return "\n".join(out) + "\n"


_LITERAL = re.compile(r"::\n\n((?:    .*\n|\n)+)")  # a reST literal block, indented by four


def _toml(literal: re.Match[str]) -> str:
    return "```toml\n" + re.sub(r"^    ", "", literal.group(1), flags=re.M).strip("\n") + "\n```"


def _bus_example(doc: str) -> str:
    """The ``[bus]`` example of pyrhonn/buslog.py's docstring as a TOML block."""
    block = _LITERAL.search(doc)
    if block is None:
        raise ValueError("pyrhonn/buslog.py: its docstring has no [bus] example to show")
    return _toml(block)


def _config_page() -> str:
    from pyrhonn import buslog, configfile

    rst_role = re.compile(r":(?:class|func|mod|meth|data|attr):`~?([^`]+)`")
    doc = rst_role.sub(r"`\1`", (configfile.__doc__ or "").replace("``", "`"))  # reST to Markdown
    title, _, body = doc.strip().partition("\n")
    example, _, rules = body.partition("Rules\n-----")
    example = _LITERAL.sub(lambda m: ":\n\n" + _toml(m) + "\n\n", example + "\n")
    keys = [
        ("top level", configfile._TOP_KEYS),
        ("`[defaults]` (inherited by every neuron)", configfile.TUNING_KEYS + configfile.PROTECTION_KEYS),
        ("each `[[neurons]]` table", configfile._NEURON_KEYS),
    ]
    out = ["# Config file reference", "", "Generated from `pyrhonn/configfile.py` when the site is built.", "",
           title, "", "## Keys", "", "| table | keys accepted |",
           "| --- | --- |"]
    keys.append(("`[bus]` (for `pyrhonn identify --can-log`)", buslog._KEYS))
    out += [f"| {where} | {', '.join(f'`{k}`' for k in ks)} |" for where, ks in keys]
    out += ["", "Any other key is an error that names it.", "", "## Example", "",
            example.strip(), "", "## Rules", "", rules.strip(), "", "## The `[bus]` table", "",
            "From `pyrhonn/buslog.py`, which has the rules for lost, late and flagged frames "
            "([a bus recording](../can-log.md) walks through them):", "", _bus_example(buslog.__doc__ or ""), ""]
    return "\n".join(out)


_PROTOTYPE = re.compile(r"^(?:const )?\w+[ *]+(rhonn_\w+)\s*\(")


def _functions(text: str) -> list[tuple[str, str, str]]:
    """``(name, prototype, comment)`` of every function a header declares, in order. A comment
    documents the prototypes that follow it directly (a getter and its setter share one)."""
    out: list[tuple[str, str, str]] = []
    lines = text.splitlines()
    comment, i = "", 0
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith("/*"):
            block = [line]
            while "*/" not in block[-1] and i + 1 < len(lines):
                i += 1
                block.append(lines[i])
            body = "\n".join(block).strip()[2:-2]
            comment = "\n".join(re.sub(r"^\s*\* ?", "", ln).rstrip() for ln in body.strip("*\n ").splitlines())
        elif _PROTOTYPE.match(line):
            decl = [line]
            while ";" not in decl[-1] and i + 1 < len(lines):
                i += 1
                decl.append(lines[i])
            name = _PROTOTYPE.match(line).group(1)
            out.append((name, " ".join(" ".join(decl).split()), comment.strip()))
        elif line.strip():
            comment = ""  # anything else between a comment and a prototype: the comment is not its
        i += 1
    return out


def _c_page() -> str:
    out = ["# C API reference", "",
           "Generated from the headers in `csrc/include/` when the site is built: first every "
           "function with the comment that documents it, then each header whole (its opening "
           "comment explains the step's order, the errors and the precision).", ""]
    for name in HEADERS:
        text = (ROOT / "csrc" / "include" / name).read_text(encoding="utf-8")
        out.extend([f"## `{name}`", ""])
        for fn, decl, comment in _functions(text):
            out.extend([f"### `{fn}`", "", "```c", decl, "```", ""])
            if comment:
                out.extend(["```text", comment, "```", ""])
        out.extend([f"### `{name}` in full", "", "```c", text.rstrip(), "```", ""])
    return "\n".join(out)


# Capacities whose sizeof(rhonn_t) the pages quote: the defaults of rhonn_capacity.h, those the
# Cortex-M4F image is built with (firmware_sim/cortex_m4/run_m4.py) and the smallest that hold the
# shipped firmware-lim identifier (what `pyrhonn export` writes).
_M4_CAPACITIES = {"RHONN_MAX_STATES": 6, "RHONN_MAX_INPUTS": 2, "RHONN_MAX_TERMS": 8, "RHONN_MAX_FACTORS": 2,
                  "RHONN_MAX_DELAY": 1, "RHONN_MAX_POWER": 2}


def _sizeof(defines: dict[str, int], *flags: str) -> str:
    """sizeof(rhonn_t) with these capacities and flags, from a probe compiled with the host's cc
    against csrc/include (x86-64, AArch64 and Arm EABI lay rhonn_t out alike)."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory(prefix="pyrhonn-docs-") as tmp:
        probe = Path(tmp) / "probe.c"
        probe.write_text('#include <stdio.h>\n#include "rhonn.h"\n'
                         'int main(void) { printf("%lu", (unsigned long)sizeof(rhonn_t)); return 0; }\n')
        subprocess.run(["cc", "-std=c99", *flags, *(f"-D{k}={v}" for k, v in defines.items()),
                        f"-I{ROOT / 'csrc' / 'include'}", str(probe), "-o", str(probe.with_suffix(""))],
                       check=True, capture_output=True)
        out = subprocess.run([str(probe.with_suffix(""))], check=True, capture_output=True, text=True).stdout
    return f"{int(out):,}"


def _package_sizes() -> dict[str, str]:
    """The sizes of the package's own builds, as ``pyrhonn info --json`` reports them: for the
    build with the firmware default capacities ("small") and the one sized for structure search
    ("large"), per precision, the vector lanes' workspace (``rhonn_population_work``, which
    ``step`` allocates per identifier) and ``sizeof(rhonn_t)``; kB and MB of 1,000 and 1,000,000 bytes."""
    import subprocess
    import sys

    info = json.loads(subprocess.run([sys.executable, "-m", "pyrhonn.cli", "info", "--json"], check=True,
                                     capture_output=True, text=True).stdout)
    out = {}
    for build in info["builds"]:
        size = "small" if build["module"].startswith("pyrhonn._rhonn_small_") else "large"
        work, net = build["sizeof_population_work"], build["sizeof_rhonn_t"]
        out[f"lanes_workspace.{size}.{build['dtype']}.kB"] = f"{work / 1e3:.0f}"
        out[f"lanes_workspace.{size}.{build['dtype']}.MB"] = f"{work / 1e6:.1f}"
        out[f"sizeof_rhonn_t.{size}.{build['dtype']}.kB"] = f"{net / 1e3:.0f}"
        out[f"sizeof_rhonn_t.{size}.{build['dtype']}.MB"] = f"{net / 1e6:.1f}"
    return out


def _measured() -> dict[str, str]:
    from pyrhonn.configfile import load_named
    from pyrhonn.export import min_capacities

    lim = min_capacities(load_named("firmware-lim").config)
    single, const = "-DRHONN_SINGLE", "-DRHONN_CONST_CONFIG=1"
    return {
        **_package_sizes(),
        "sizeof_rhonn_t.float64": _sizeof({}),
        "sizeof_rhonn_t.float32": _sizeof({}, single),
        "sizeof_rhonn_t.float32.const": _sizeof({}, single, const),
        "sizeof_rhonn_t.m4": _sizeof(_M4_CAPACITIES, single),
        "sizeof_rhonn_t.m4.const": _sizeof(_M4_CAPACITIES, single, const),
        "sizeof_rhonn_t.firmware_lim.float32": _sizeof(lim, single),
        "sizeof_rhonn_t.firmware_lim.float64": _sizeof(lim),
        "firmware_lim.capacities": ", ".join(f"`{k} {v}`" for k, v in lim.items()),
    }


# Pages other parts of the project add: each joins its section of the navigation once it exists
# (a nav entry for a missing page would fail the strict build). CHANGELOG.md at the top of the
# repository becomes the site's changelog.md.
OPTIONAL_PAGES = (
    ("How-to guides", "Run the identifier as an FMU", "fmu.md"),
    ("How-to guides", "Calibrate and measure over XCP", "xcp.md"),
    ("How-to guides", "Work with recordings", "recordings.md"),
    ("How-to guides", "Read HIL verdicts", "hil-verdicts.md"),
    ("Contributing", "Development", "development.md"),
    ("Contributing", "Changelog", "changelog.md"),
)


def on_config(config: Any) -> Any:
    docs = Path(config["docs_dir"])
    present = {page for _, _, page in OPTIONAL_PAGES if (docs / page).is_file()}
    if (ROOT / "CHANGELOG.md").is_file() and not (docs / "changelog.md").exists():
        present.add("changelog.md")
    listed = set(_walk(config["nav"] or []))
    for section, title, page in OPTIONAL_PAGES:
        if page not in present or page in listed:
            continue
        for entry in config["nav"]:
            if isinstance(entry, dict) and section in entry:
                entry[section].append({title: page})
                break
        else:
            config["nav"].append({section: [{title: page}]})
    return config


def _walk(nav: list[Any]) -> list[str]:
    """Every page file named in a nav (sub)tree."""
    out: list[str] = []
    for entry in nav:
        if isinstance(entry, str):
            out.append(entry)
        elif isinstance(entry, dict):
            for value in entry.values():
                out.extend(_walk(value) if isinstance(value, list) else [value])
    return out


def on_files(files: Files, config: Any) -> Files:
    pages = {"reference/cli.md": _cli_page(), "reference/config.md": _config_page(),
             "reference/c-api.md": _c_page()}
    for uri, content in pages.items():
        files.append(File.generated(config, uri, content=content))
    if (ROOT / "CHANGELOG.md").is_file() and files.get_file_from_path("changelog.md") is None:
        text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")  # its links are relative to the top
        files.append(File.generated(config, "changelog.md", content=re.sub(r"\]\(docs/", "](", text)))
    for png in sorted((ROOT / "hil" / "docs").glob("*.png")):
        files.append(File.generated(config, f"hil/docs/{png.name}", abs_src_path=str(png)))
    return files


RESULTS = ROOT / "bench" / "results"
#: ``{{ bench("NAME", "a.b.c") }}`` or ``{{ bench("NAME", "a.b.c", "SPEC") }}``, SPEC a format spec
#: ``{{ bench_run("NAME", "load.start.0") }}``: the same from the run's record (date, command, machine, load)
BENCH_REF = re.compile(r'\{\{ bench(_run)?\("(\w+)", "([^"]+)"(?:, "([^"]*)")?\) \}\}')
_RESULTS_CACHE: dict[Path, dict[str, Any]] = {}


def _results(name: str, folder: Path) -> dict[str, Any]:
    file = folder / f"{name}.json"
    if file not in _RESULTS_CACHE:
        if not file.is_file():
            raise ValueError(f"bench/results/{name}.json: no such results file "
                             f"(python bench/bench_{name}.py --results writes it)")
        data = json.loads(file.read_text(encoding="utf-8"))
        if not isinstance(data, dict) or not isinstance(data.get("figures"), dict):
            raise ValueError(f"bench/results/{name}.json: no 'figures' mapping")
        _RESULTS_CACHE[file] = data
    return _RESULTS_CACHE[file]


def format_figure(value: Any, spec: str | None) -> str:
    """A figure as a page shows it: ``spec`` is a Python format spec (a trailing ``%`` is
    written `` %``, as the pages do), after a divisor if it starts with one (``/1e3:.2f``: a
    time in ns shown in µs); without one, an integer with thousands separators,
    a float with none of its decimals from 100 on and 3 significant digits below."""
    if isinstance(value, bool) or value is None or isinstance(value, (dict, list)):
        if spec is None and isinstance(value, bool):
            return "yes" if value else "no"
        raise ValueError(f"not a number or text: {value!r}")
    if spec is not None and spec.startswith("/"):  # "/1e3:.2f": ns shown in µs
        divisor, _, spec = spec[1:].partition(":")
        if not isinstance(value, (int, float)) or not spec:
            raise ValueError(f"a scaled format needs a number and a spec after ':', got {value!r} and {spec!r}")
        value = value / float(divisor)
    if spec is not None:
        text = re.sub(r"e([+-])0(\d)", r"e\1\2", format(value, spec))  # 1.70e-5, as the pages write it
        return text[:-1] + " %" if spec.endswith("%") else text
    if isinstance(value, int):
        return f"{value:,}"
    if isinstance(value, float):
        return f"{value:,.0f}" if abs(value) >= 100 else f"{value:.3g}"
    return str(value)


def bench_figure(name: str, path: str, spec: str | None = None, folder: Path | None = None,
                 run: bool = False) -> str:
    """The figure ``path`` (keys joined by dots) of ``bench/results/NAME.json``, formatted; with
    ``run``, ``path`` is read from the run's record around the figures (``load.start.0``)."""
    record = _results(name, folder or RESULTS)
    value: Any = record if run else record["figures"]
    for part in path.split("."):
        if isinstance(value, dict) and part in value:
            value = value[part]
        elif isinstance(value, list) and part.isdigit() and int(part) < len(value):
            value = value[int(part)]
        else:
            raise ValueError(f"bench/results/{name}.json: no figure {path!r} (no {part!r})")
    try:
        return format_figure(value, spec)
    except ValueError as exc:
        raise ValueError(f"bench/results/{name}.json: figure {path!r}: {exc}") from None


def render_bench(markdown: str, folder: Path | None = None) -> str:
    """``markdown`` with every ``{{ bench(...) }}`` replaced by its figure."""
    return BENCH_REF.sub(lambda m: bench_figure(m.group(2), m.group(3), m.group(4), folder, bool(m.group(1))),
                         markdown)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    if "{{ " not in markdown:
        return markdown
    try:
        markdown = render_bench(markdown)
    except ValueError as exc:
        raise ValueError(f"{page.file.src_uri}: {exc}") from None
    if "{{ " not in markdown:
        return markdown
    global _MEASURED
    if _MEASURED is None:
        _MEASURED = _measured()
    for key, value in _MEASURED.items():
        markdown = markdown.replace("{{ " + key + " }}", value)
    left = re.findall(r"\{\{ [\w.]+ \}\}|\{\{ bench\(.*?\}\}", markdown)
    if left:
        raise ValueError(f"{page.file.src_uri}: no measured figure for {', '.join(left)}")
    return markdown


_MEASURED: dict[str, str] | None = None


_ROLE_HTML = re.compile(r":(?:class|func|meth|mod|attr|data|exc|obj):(<code>)~?")


def on_page_content(html: str, page: Any, config: Any, files: Files) -> str:
    """The docstrings' reST roles (``:class:`~pyrhonn.x```) as plain code in the API pages."""
    return _ROLE_HTML.sub(r"\1", html)
