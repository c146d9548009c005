"""Build rhonn_runner with the host C compiler, without CMake: for the
benchmark, the tests and ``pyrhonn hil`` when no CMake build is at hand.

    python firmware_sim/linux/build_runner.py OUT_DIR
    python firmware_sim/linux/build_runner.py --config ID.toml --dbc ID.dbc OUT_DIR

The sources and flags are those of the CMake target ``rhonn_runner``
(firmware_sim/CMakeLists.txt): the application on the float core, with the
udp_multicast codec. :func:`cached` builds once per content of the sources
(and compiler, flags) into a cache directory and reuses that build after.

With ``--config`` and ``--dbc`` (:func:`build_for`, :func:`cached_for`) the
runner is the firmware of another identifier: a config file of ``pyrhonn
select``/``tune`` (float32) and the DBC ``pyrhonn export --dbc`` wrote for it.
OUT_DIR then also holds the protocol generated from that DBC
(tools/generate_protocol.py) and the identifier's header (pyrhonn.export),
which the build reads before the committed LIM files.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[2]
FW = ROOT / "firmware_sim"
INCLUDE_DIRS = [ROOT / "csrc" / "include", FW / "app", FW / "generated", FW / "config", FW / "linux"]
SOURCES = [FW / "linux" / "rhonn_runner.c", FW / "linux" / "udp_can.c", FW / "app" / "fw_app.c",
           FW / "app" / "fw_protocol.c", FW / "app" / "fw_secoc.c", FW / "app" / "fw_aes_cmac.c", FW / "app" / "fw_xcp.c",
           FW / "generated" / "rhonn_id.c", ROOT / "csrc" / "src" / "rhonn.c"]
FLAGS = ["-std=c99", "-O2", "-ffp-contract=off", "-DRHONN_SINGLE"]


def _compiler() -> str:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (cc) on PATH")
    return cc


def build(out_dir: Path, protocol_dir: Path | None = None) -> Path:
    """Compile the runner into ``out_dir``; its path. ``protocol_dir``: a folder written by
    :func:`write_identifier_sources` (another identifier), else the LIM's. RuntimeError without cc,
    subprocess.CalledProcessError when the compiler fails (its messages on stderr)."""
    cc = _compiler()
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    exe = Path(out_dir) / "rhonn_runner"
    includes, sources, flags = list(INCLUDE_DIRS), list(SOURCES), list(FLAGS)
    if protocol_dir is not None:
        protocol_dir = Path(protocol_dir).resolve()
        includes.insert(0, protocol_dir)
        sources = [protocol_dir / "rhonn_id.c" if p == FW / "generated" / "rhonn_id.c" else p for p in sources]
        flags.append(f'-DFW_IDENTIFIER_HEADER="{IDENTIFIER_HEADER}"')
    cmd = [cc, *flags, *(f"-I{d}" for d in includes), *map(str, sources), "-lm", "-o", str(exe)]
    subprocess.run(cmd, check=True)
    return exe


#: the identifier's header in a protocol folder (static const rhonn_config FW_IDENTIFIER)
IDENTIFIER_HEADER = "fw_identifier.h"


def write_identifier_sources(out_dir: Path, config_path: Path, dbc_path: Path) -> list[Path]:
    """The protocol of ``dbc_path`` (tools/generate_protocol.py) and the float32 identifier of the
    config file ``config_path`` as FW_IDENTIFIER, into ``out_dir``; ValueError (naming the file) when
    the config is not float32, does not match the DBC's states and inputs, or the DBC has not the
    protocol's shape."""
    import importlib.util

    from pyrhonn.configfile import load_config
    from pyrhonn.export import header_text

    spec = importlib.util.spec_from_file_location("_fw_generate_protocol", FW / "tools" / "generate_protocol.py")
    gen = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(gen)
    import cantools

    cf = load_config(config_path)
    if cf.config.dtype != "float32":
        raise ValueError(f"{config_path}: dtype is {cf.config.dtype!r}; the firmware runs the float32 core")
    try:
        states, inputs = gen.layout(cantools.database.load_file(str(dbc_path)))
    except (OSError, ValueError, KeyError) as exc:
        raise ValueError(f"{dbc_path}: {exc}") from None
    if list(states) != list(cf.state_names) or list(inputs) != list(cf.input_names):
        raise ValueError(f"{dbc_path}: carries states {states} and inputs {inputs}; {config_path} identifies "
                         f"states {list(cf.state_names)} and inputs {list(cf.input_names)}")
    out = Path(out_dir)
    written = gen.generate(out, Path(dbc_path))
    header = out / IDENTIFIER_HEADER
    header.write_text(header_text(cf.config, "FW_IDENTIFIER"))
    return [*written, header]


def build_for(out_dir: Path, config_path: Path, dbc_path: Path) -> Path:
    """The runner of another identifier (see the module docstring), built in ``out_dir``; its path."""
    write_identifier_sources(out_dir, config_path, dbc_path)
    return build(out_dir, protocol_dir=out_dir)


def _fingerprint(cc: str) -> str:
    h = hashlib.sha256()
    h.update(os.path.realpath(cc).encode())
    h.update(" ".join(FLAGS).encode())
    files = sorted({*SOURCES, *(p for d in INCLUDE_DIRS for p in d.glob("*.h"))})
    for path in files:
        h.update(str(path.relative_to(ROOT)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:20]


def default_cache_dir() -> Path:
    """$PYRHONN_CACHE_DIR, else $XDG_CACHE_HOME/pyrhonn, else ~/.cache/pyrhonn."""
    if os.environ.get("PYRHONN_CACHE_DIR"):
        return Path(os.environ["PYRHONN_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "pyrhonn"


def build_once(cache_dir: Path | None, name: str, built: str, make: Callable[[Path], object]) -> Path:
    """``cache_dir / name / built`` (``cache_dir`` default :func:`default_cache_dir`), made by
    ``make(folder)`` into a fresh folder renamed into place unless it is already there (atomically:
    parallel callers are safe, the first to finish wins)."""
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    final = cache / name
    if (final / built).is_file():
        return final / built
    cache.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".building-", dir=cache))
    try:
        make(work)
        try:
            os.rename(work, final)
        except OSError:  # another process finished first: use its build
            if not (final / built).is_file():
                raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return final / built


def cached(cache_dir: Path | None = None) -> Path:
    """The runner built from the current sources: reused from ``cache_dir``
    (default :func:`default_cache_dir`) when a build of exactly these sources
    is there, else built into it (atomically: parallel callers are safe)."""
    cc = _compiler()
    return build_once(cache_dir, f"rhonn_runner-{_fingerprint(cc)}", "rhonn_runner", build)


def cached_for(config_path: Path, dbc_path: Path, cache_dir: Path | None = None) -> Path:
    """:func:`build_for` once per content of the sources, the config file and the DBC, reused after
    (as :func:`cached`)."""
    cc = _compiler()
    h = hashlib.sha256(_fingerprint(cc).encode())
    for path in (config_path, dbc_path, FW / "tools" / "generate_protocol.py"):
        h.update(Path(path).read_bytes())
    return build_once(cache_dir, f"rhonn_runner-id-{h.hexdigest()[:20]}", "rhonn_runner",
                      lambda work: build_for(work, config_path, dbc_path))


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--config", type=Path, help="another identifier's config file (float32); needs --dbc")
    ap.add_argument("--dbc", type=Path, help="the DBC pyrhonn export --dbc wrote for it; needs --config")
    args = ap.parse_args()
    if (args.config is None) != (args.dbc is None):
        ap.error("--config and --dbc: give both or neither")
    try:
        exe = build(args.out_dir) if args.config is None else build_for(args.out_dir, args.config, args.dbc)
    except ValueError as exc:
        ap.error(str(exc))
    print(exe)
