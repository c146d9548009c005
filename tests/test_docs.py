"""The project stands on its own: no pointers to files outside it, no issue
numbers, every docs/plants.md section that code or docs link to exists, and
docs/plants.md states the numbers the code uses. Every code example of the
README and the docs runs as written, and the README links only to files that
exist."""
from __future__ import annotations

import ast
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import pytest
from source_scripts import load_script  # noqa: E402

from pyrhonn.plants import lim, robot

from docs_blocks import code_blocks, run, transcript_matches, transcript_steps

ROOT = Path(__file__).resolve().parents[1]
PLANTS_MD = ROOT / "docs" / "plants.md"
THIS_FILE = Path(__file__).resolve().relative_to(ROOT).as_posix()

#: What a user must never see: developers' notes and their numbered sections,
#: the project's own issue numbers (an upstream "optuna issue #4002" is fine),
#: and absolute paths of a machine. (Each pattern is written so that it does not
#: match itself: a one-letter class breaks the literal, the meaning is the same.)
FORBIDDEN = {
    "developers' plant notes": r"share[d]/plants|plant notes|plants\.md §",
    "an issue number": r"\bissu[e] [0-9]",
    "a machine path": r"/wor[k]/|/home/[A-Za-z0-9_.-]+|/root/|/Users/[A-Za-z0-9_.-]+|[A-Za-z]:\\Users\\",
}
ANCHOR_REF = re.compile(r"plants\.md#([A-Za-z0-9_-]+)")


def _git(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=False)


@pytest.fixture(scope="module")
def checkout() -> Path:
    if _git("rev-parse", "--is-inside-work-tree").stdout.strip() != "true":
        pytest.skip("needs the project's git checkout (git grep over its files)")
    return ROOT


def _grep(pattern: str) -> list[str]:
    """``file:line:text`` of every tracked text file (as it is in the working tree) matching
    ``pattern``, case-insensitive, this file excluded. Untracked files are left out: run
    outputs (a reproduce folder, hil logs) may hold this machine's paths and are not shipped."""
    res = _git("grep", "-nIiE", pattern, "--", ".", f":(exclude){THIS_FILE}")
    assert res.returncode in (0, 1), res.stderr  # 1: no match
    return res.stdout.splitlines()


def anchors(markdown: str) -> set[str]:
    """The link targets a Markdown page defines: explicit ``<a id="...">`` and
    GitHub's heading slugs (lower case, punctuation dropped, spaces to dashes)."""
    ids = set(re.findall(r'<a\s+id="([^"]+)"', markdown))
    for heading in re.findall(r"^#{1,6}\s+(.+?)\s*$", markdown, flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
        ids.add(slug)
    return ids


def test_forbidden_patterns_catch_what_they_are_for():
    hits = {
        "developers' plant notes": ["see /x/shared" "/plants.md", "the plant notes say", "plants.md §1.2"],
        "an issue number": ["Issue" " 4's targets", "fixed in issue" " 12"],
        "a machine path": ["/wor" "k/main/README.md", "/home/alice/x", "/root/.cache", "C:\\Users\\bob"],
    }
    for what, texts in hits.items():
        for text in texts:
            assert re.search(FORBIDDEN[what], text, flags=re.I), (what, text)
    for text in ("optuna issue #4002", "docs/plants.md#lim-rig", "the homework", "framework/"):
        assert not any(re.search(p, text, flags=re.I) for p in FORBIDDEN.values()), text


@pytest.mark.parametrize("what", sorted(FORBIDDEN))
def test_project_references_no_outside_files_or_issue_numbers(checkout, what):
    hits = _grep(FORBIDDEN[what])
    assert not hits, f"{what} in the project:\n" + "\n".join(hits)


def test_anchor_parser_reads_ids_and_heading_slugs():
    text = '<a id="lim-rig"></a>\n## The 0.3 ms LIM rig (the real-time test)\n### Model\n'
    assert anchors(text) == {"lim-rig", "the-03-ms-lim-rig-the-real-time-test", "model"}


def test_every_plants_md_anchor_referenced_exists(checkout):
    defined = anchors(PLANTS_MD.read_text(encoding="utf-8"))
    refs: dict[str, list[str]] = {}
    for hit in _grep(r"plants\.md#[A-Za-z0-9_-]+"):
        where = hit.split(":", 2)
        for anchor in ANCHOR_REF.findall(where[2]):
            refs.setdefault(anchor, []).append(f"{where[0]}:{where[1]}")
    # the plant modules, the observer and the configs all point into the page
    referring = {loc.split(":")[0] for locs in refs.values() for loc in locs}
    for path in ("pyrhonn/plants/lim.py", "pyrhonn/plants/robot.py", "pyrhonn/plants/oscillator.py",
                 "pyrhonn/baselines/honn_observer.py", "pyrhonn/configs/example3.toml"):
        assert path in referring, f"{path} no longer links to docs/plants.md"
    missing = {a: locs for a, locs in refs.items() if a not in defined}
    assert not missing, "docs/plants.md has no section for: " + "; ".join(
        f"#{a} (from {', '.join(locs)})" for a, locs in sorted(missing.items()))


def _section(markdown: str, anchor: str) -> str:
    """The text of docs/plants.md from ``<a id="anchor">`` to the next explicit anchor."""
    start = markdown.index(f'<a id="{anchor}"></a>')
    nxt = markdown.find('<a id="', start + 1)
    return markdown[start:nxt if nxt >= 0 else None]


def _table_values(section: str) -> dict[str, float]:
    """``{field: value}`` from the rows of a parameter table: the code column
    (2nd) names the field(s) in backticks, the 4th column holds the number."""
    out: dict[str, float] = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 4 or not cells[1].startswith("`"):
            continue
        for name in re.findall(r"`([A-Za-z_0-9]+)`", cells[1]):
            out[name] = float(cells[3].replace(",", ""))
    return out


@pytest.mark.parametrize("anchor, params", [("lim-parameters", lim.LimParams()),
                                            ("robot-parameters", robot.RobotParams())])
def test_plants_md_parameter_tables_match_the_code_defaults(anchor, params):
    table = _table_values(_section(PLANTS_MD.read_text(encoding="utf-8"), anchor))
    names = {f.name for f in fields(params)}
    assert set(table) == names, f"#{anchor}: table rows {sorted(table)} vs fields {sorted(names)}"
    for name, value in table.items():
        assert getattr(params, name) == pytest.approx(value, rel=1e-12), f"#{anchor}: {name}"


def test_plants_md_lim_constants_match_the_code():
    text = _section(PLANTS_MD.read_text(encoding="utf-8"), "lim-parameters")
    stated = dict(re.findall(r"\b(k\d+) = (-?[0-9]+(?:\.[0-9]+)?(?:e-?[0-9]+)?)", text.split("Derived", 1)[1]))
    k = lim.LimParams().constants()
    assert set(stated) == {f.name for f in fields(k)}
    for name, value in stated.items():
        digits = len(value.lstrip("-").split("e")[0].replace(".", "").lstrip("0"))
        assert getattr(k, name) == pytest.approx(float(value), rel=0.6 * 10.0 ** (1 - digits)), name


# -- every code example of the README and the docs site runs ----------------------------------------
#
# The convention (stated in docs/contributing-docs.md):
# - ```python blocks are executed, ```bash blocks run with `bash -e`, ```c blocks compiled against the
#   core (csrc/include); a page's blocks run in order in one fresh folder (a later block may use a file
#   an earlier one wrote), with `csrc` and `firmware_sim` linked into it and the installed `pyrhonn` on PATH.
# - `<!-- docs-test: file NAME -->` on the line before a block writes the block to NAME instead (a C
#   file a later ```bash block builds, a CSV a command reads); an unnamed ```c block is compiled alone.
# - `<!-- docs-test: transcript -->` before a ```console block runs each `$ ` command in it and
#   requires the lines after it, up to the next `$ ` line, to be what the command prints (a line
#   `...` stands for lines left out).
# - `<!-- docs-test: by FILE::TEST -->` before a block whose command needs what this test process
#   does not have (a CAN interface, the VM tier, a database, a running runner, a long run): the named
#   test of tests/FILE reads this block from the page (docs_blocks.blocks_by) and runs or checks it; a
#   ```console block so marked is a transcript that test runs and compares (docs_blocks.transcript_matches).
# - `<!-- docs-test: skip REASON -->` before a block that is not a command (an excerpt of a written
#   file); a REASON is required.
# - ```toml, ```csv, ```text and unnamed blocks are shown, not run. No page holds a ```sh block or a
#   ```console block that is not a transcript (here or by a test): each command is run by one of the rules above.

PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md")])
RUNNABLE = ("python", "bash", "c")
MARKERS = ("skip", "file", "transcript", "by")
CC = shutil.which("cc") or shutil.which("gcc")


def test_code_block_reader_reads_languages_markers_and_bodies():
    text = ("intro\n```python\nprint(1)\n```\n<!-- docs-test: by test_x.py::test_y -->\n```bash\ncandump x\n```\n"
            "<!-- docs-test: file app.c -->\n```c\nint main(void) { return 0; }\n```\n```console\n$ ls\n```\n")
    assert code_blocks(text) == [("python", "print(1)\n", None, None), ("bash", "candump x\n", "by", "test_x.py::test_y"),
                                 ("c", "int main(void) { return 0; }\n", "file", "app.c"),
                                 ("console", "$ ls\n", None, None)]


def _runnable_pages() -> list[Path]:
    return [p for p in PAGES if any((lang in RUNNABLE and marker not in ("skip", "by")) or marker == "transcript"
                                    for lang, _, marker, _ in code_blocks(p.read_text(encoding="utf-8")))]


def test_transcript_reader_pairs_commands_with_their_output():
    assert transcript_steps("$ a x\none\ntwo  \n$ b\n") == [("a x", "one\ntwo"), ("b", "")]


def test_a_transcript_line_of_dots_stands_for_lines_left_out_and_nothing_else():
    printed = "head\n  a 1\n  b 2\n  c 3  \n"
    assert transcript_matches(printed, "head\n  a 1\n  b 2\n  c 3")
    assert transcript_matches(printed, "head\n  a 1\n  ...")
    assert transcript_matches(printed, "head\n...\n  c 3")
    assert transcript_matches(printed, "head\n  a 1\n...\n  b 2\n  c 3")      # none left out
    assert not transcript_matches(printed, "head\n  a 1")                     # the rest is not shown
    assert not transcript_matches(printed, "head\n  a 9\n  ...")             # a shown line differs
    assert not transcript_matches(printed, "...\n  b 2")


def test_markers_name_a_known_action_with_its_argument():
    for page in PAGES:
        for lang, body, marker, arg in code_blocks(page.read_text(encoding="utf-8")):
            where = f"{page.relative_to(ROOT)}: a ```{lang} block"
            assert marker in (None, *MARKERS), f"{where}: unknown marker {marker!r}"
            assert (marker in (None, "transcript")) == (not arg), \
                f"{where}: `docs-test: {marker}` takes {'no argument' if marker == 'transcript' else 'a reason or file name'}"
            if marker == "transcript":
                assert lang == "console" and body.startswith("$ "), f"{where}: a transcript is a ```console block of `$ ` lines"
            if marker == "file":
                assert "/" not in arg and not arg.startswith("."), f"{where}: file {arg!r} must be a plain name"
            if marker == "by":
                assert re.fullmatch(r"test_\w+\.py::test_\w+", arg), f"{where}: `by` names FILE.py::TEST, not {arg!r}"


#: Blocks still shown without a test, by page and first line (none now). The list only shrinks: an
#: entry whose block is gone or runs fails the test below.
NOT_YET_RUN: set[tuple[str, str]] = set()


def test_no_page_shows_a_command_that_no_test_runs():
    # a ```sh block or a bare ```console block would be shown and never run: it would go stale (a
    # console block marked `by` is run by its test, which compares what it prints with the page)
    shown = {(page.relative_to(ROOT).as_posix(), body.splitlines()[0] if body else "")
             for page in PAGES for lang, body, marker, _ in code_blocks(page.read_text(encoding="utf-8"))
             if lang in ("sh", "shell", "zsh") or (lang == "console" and marker not in ("transcript", "by"))}
    new = sorted(shown - NOT_YET_RUN)
    assert not new, "commands no test runs (see docs/contributing-docs.md):\n" + "\n".join(f"{p}: {f}" for p, f in new)
    assert not NOT_YET_RUN - shown, f"run now or gone, take them off NOT_YET_RUN: {sorted(NOT_YET_RUN - shown)}"


def _test_reads_block(source: str, test: str, page: str, label: str) -> bool:
    """Whether the function ``test`` of a test file's ``source`` calls ``blocks_by`` and names both
    ``page`` and ``label`` (as string literals: directly in the call, or in a variable it passes)."""
    for node in ast.parse(source).body:
        if isinstance(node, ast.FunctionDef) and node.name == test:
            calls = any(isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "blocks_by"
                        for n in ast.walk(node))
            literals = {n.value for n in ast.walk(node) if isinstance(n, ast.Constant)}
            return calls and {page, label} <= literals
    return False


def test_reader_of_by_markers_finds_the_call_in_the_named_test():
    src = ('def test_a():\n    body = blocks_by("docs/x.md", "test_f.py::test_a")\n\ndef test_b():\n    pass\n'
           'def test_c():\n    label = "test_f.py::test_c"\n    return [blocks_by(p, label) for p in ("docs/x.md",)]\n'
           'def test_d():\n    return "docs/x.md", "test_f.py::test_d"\n')
    assert _test_reads_block(src, "test_a", "docs/x.md", "test_f.py::test_a")
    assert _test_reads_block(src, "test_c", "docs/x.md", "test_f.py::test_c")
    assert not _test_reads_block(src, "test_b", "docs/x.md", "test_f.py::test_b")
    assert not _test_reads_block(src, "test_a", "docs/y.md", "test_f.py::test_a")
    assert not _test_reads_block(src, "test_d", "docs/x.md", "test_f.py::test_d")   # names it, reads nothing


def test_every_by_marker_names_a_test_that_reads_the_block_from_the_page():
    found = 0
    for page in PAGES:
        name = page.relative_to(ROOT).as_posix()
        for _, _, marker, arg in code_blocks(page.read_text(encoding="utf-8")):
            if marker != "by":
                continue
            found += 1
            file, test = arg.split("::")
            path = ROOT / "tests" / file
            assert path.exists(), f"{name}: `docs-test: by {arg}`: there is no tests/{file}"
            assert _test_reads_block(path.read_text(encoding="utf-8"), test, name, arg), \
                f"{name}: `docs-test: by {arg}`: tests/{file} has no {test} that calls blocks_by({name!r}, {arg!r})"
    assert found, "no block is marked `docs-test: by`"


def test_readme_and_docs_hold_runnable_examples():
    # the README's three journeys at least: a change of fence or marker must not make them vanish
    langs = [lang for lang, _, marker, _ in code_blocks((ROOT / "README.md").read_text(encoding="utf-8"))
             if marker != "skip"]
    assert {"python", "bash", "c"} <= set(langs), langs
    assert len(_runnable_pages()) >= 3


@pytest.mark.parametrize("page", _runnable_pages(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_code_examples_run_as_written(page: Path, tmp_path: Path) -> None:
    if CC is None:
        pytest.skip("no C compiler (cc) on PATH")
    for folder in ("csrc", "firmware_sim"):   # the top folder of a checkout, as the pages' commands expect
        (tmp_path / folder).symlink_to(ROOT / folder, target_is_directory=True)
    for n, (lang, body, marker, arg) in enumerate(code_blocks(page.read_text(encoding="utf-8"))):
        what = f"{page.relative_to(ROOT)}, block {n + 1} (```{lang})"
        if marker in ("skip", "by"):
            continue
        if marker == "file":
            (tmp_path / arg).write_text(body, encoding="utf-8")
            continue
        if marker == "transcript":
            for cmd, expected in transcript_steps(body):
                printed = run(["bash", "-ec", cmd], tmp_path, what)
                assert transcript_matches(printed, expected), f"{what}: `{cmd}` prints\n{printed}\nnot\n{expected}"
            continue
        if lang == "python":
            script = tmp_path / f"block{n + 1}.py"
            script.write_text(body, encoding="utf-8")
            run([sys.executable, script.name], tmp_path, what)
        elif lang == "bash":
            script = tmp_path / f"block{n + 1}.sh"
            script.write_text(body, encoding="utf-8")
            run(["bash", "-e", script.name], tmp_path, what)
        elif lang == "c":
            source = tmp_path / f"block{n + 1}.c"
            source.write_text(body, encoding="utf-8")
            run([*shlex.split(CC), "-std=c99", "-Wall", "-Werror", "-fsyntax-only", f"-I{ROOT / 'csrc' / 'include'}",
                  "-I.", source.name], tmp_path, what)


def test_readme_links_point_to_files_of_the_repository():
    # on a code host the README is read as it is: its links must reach files that exist, not pages
    # the site generates when it is built
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = [t.split("#")[0] for t in re.findall(r"\]\(([^)\s]+)\)", text) if "://" not in t and not t.startswith("#")]
    assert targets, "the README links to nothing"
    missing = [t for t in targets if not (ROOT / t).exists()]
    assert not missing, f"README.md links to missing files: {missing}"


def _docs_hooks():
    """docs_hooks.py, the MkDocs hook that generates the reference pages (loaded from its file: it is
    not part of the package)."""
    pytest.importorskip("mkdocs")
    return load_script(ROOT / "docs_hooks.py", "docs_hooks")


def test_c_api_reference_documents_every_function_of_the_headers():
    hooks = _docs_hooks()
    page = hooks._c_page()
    for header in (ROOT / "csrc" / "include").glob("*.h"):
        assert header.name in hooks.HEADERS, f"{header.name} is missing from the C API reference"
        declared = set(re.findall(r"^(?:const )?\w+[ *]+(rhonn_\w+)\s*\(", header.read_text(encoding="utf-8"), re.M))
        for name in declared:
            assert f"### `{name}`" in page, f"{header.name}: {name} has no entry in the C API reference"
    # a getter and its setter under one comment both carry it
    weights = page.split("### `rhonn_set_weights`", 1)[1].split("###", 1)[0]
    assert "ROUND TRIP" in weights


def test_cli_reference_holds_every_command_and_option():
    from pyrhonn.cli import build_parser

    page = _docs_hooks()._cli_page()
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    for name, child in sub.choices.items():
        assert f"`pyrhonn {name}`" in page, name
        for action in child._actions:
            for option in action.option_strings:
                assert option in page, f"pyrhonn {name} {option}"
