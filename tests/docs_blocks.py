"""The fenced code blocks of the README and the docs pages, as the tests read them.

tests/test_docs.py runs the blocks a test process can run. A block whose command needs
what that process does not have (a CAN interface, the VM tier, a database, a long run)
carries `<!-- docs-test: by FILE::TEST -->`: that test of the suite reads the block with
:func:`blocks_by` and runs (or checks) this very text, so the page cannot drift from
what is run."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"(?:^<!-- docs-test: (?P<marker>[a-z]+)(?: (?P<arg>[^\n]*?))? -->\n)?"
                   r"^```(?P<lang>[A-Za-z0-9_+-]*)[^\n]*\n(?P<body>.*?)^```[ \t]*$", re.M | re.S)


def code_blocks(markdown: str) -> list[tuple[str, str, str | None, str | None]]:
    """``(lang, body, marker, arg)`` of every fenced block of a page, in order."""
    return [(m["lang"], m["body"], m["marker"], m["arg"]) for m in BLOCK.finditer(markdown)]


def blocks_by(page: str, test: str) -> list[str]:
    """The bodies of the blocks of ``page`` (``README.md``, ``docs/x.md``) marked
    `<!-- docs-test: by test -->`, in page order; at least one."""
    bodies = [body for _, body, marker, arg in code_blocks((ROOT / page).read_text(encoding="utf-8"))
              if marker == "by" and arg == test]
    assert bodies, f"{page} has no block marked `docs-test: by {test}`"
    return bodies


def commands(body: str) -> list[str]:
    """The command lines of a shell block: continued lines joined, comment lines and
    blank lines left out (a trailing `# comment` stays: the shell ignores it)."""
    joined = re.sub(r"\\\n\s*", " ", body)
    return [line.strip() for line in joined.splitlines() if line.strip() and not line.lstrip().startswith("#")]


def run(cmd: list[str], cwd: Path, what: str, env: dict[str, str] | None = None, timeout: float = 300) -> str:
    """Run ``cmd`` as a user would: the installed ``pyrhonn`` first on PATH, no PYTHONPATH,
    no display; fail naming ``what`` with the end of its output. Returns stdout + stderr."""
    full = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
                MPLBACKEND="Agg", **(env or {}))
    full.pop("PYTHONPATH", None)
    res = subprocess.run(cmd, cwd=cwd, env=full, capture_output=True, text=True, timeout=timeout, check=False)
    assert res.returncode == 0, f"{what} failed (exit {res.returncode}):\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res.stdout + res.stderr


def transcript_steps(body: str) -> list[tuple[str, str]]:
    """``(command, expected output)`` of each `$ ` line of a console transcript."""
    steps: list[tuple[str, list[str]]] = []
    for line in body.splitlines():
        if line.startswith("$ "):
            steps.append((line[2:], []))
        else:
            steps[-1][1].append(line.rstrip())
    return [(cmd, "\n".join(out).strip("\n")) for cmd, out in steps]


def transcript_matches(printed: str, expected: str) -> bool:
    """Whether a command's output is the transcript's: line for line (trailing blanks
    ignored), where a line `...` stands for any lines left out (none or more)."""
    pattern = ""
    for line in expected.splitlines():
        pattern += r"(?:[^\n]*\n)*?" if line.strip() == "..." else re.escape(line.rstrip()) + r"\n"
    text = "".join(line.rstrip() + "\n" for line in printed.strip("\n").splitlines())
    return re.fullmatch(pattern, text) is not None
