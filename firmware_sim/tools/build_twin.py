"""Build the Python twin of the firmware for another identifier's DBC.

    python firmware_sim/tools/build_twin.py ID.dbc [OUT_DIR]

``pyrhonn._fwapp``, the firmware application pyrhonn.firmware.FirmwareApp
runs, is compiled for the LIM's protocol (firmware_sim/rhonn_id.dbc). For a
DBC that ``pyrhonn export --dbc`` wrote for another identifier, this builds
the same application (fw_app.c, fw_protocol.c, the float32 core: the same
sources and flags) on the protocol generate_protocol.py generates from that
DBC, as a cffi module of its own. :func:`load_twin` builds it once per
content of the DBC and the sources into a cache directory (that of
build_runner.py) and imports it; :func:`protocol` returns the
:class:`pyrhonn.firmware.Protocol` that FirmwareApp takes::

    from pyrhonn.firmware import FirmwareApp
    app = FirmwareApp(bus, config, protocol=build_twin.protocol("id.dbc"))

Needs a C compiler and the source tree (csrc/, firmware_sim/, pyrhonn/_build.py).
"""
from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import shutil
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

HERE = Path(__file__).resolve().parent
FW = HERE.parent
ROOT = FW.parent


def _module(path: Path, name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise RuntimeError(f"cannot load {path}")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _fingerprint(dbc_text: bytes) -> str:
    h = hashlib.sha256(dbc_text)
    files = [ROOT / "pyrhonn" / "_build.py", HERE / "generate_protocol.py", ROOT / "csrc" / "src" / "rhonn.c",
             *sorted((FW / "app").glob("*.[ch]")), *sorted((ROOT / "csrc" / "include").glob("*.h")),
             *sorted((FW / "config").glob("*.h"))]
    for path in files:
        h.update(str(path.relative_to(ROOT)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:20]


def build(dbc: str | Path, out_dir: str | Path) -> Path:
    """Generate the protocol of ``dbc`` into ``out_dir`` and compile the twin there; the path of the
    compiled module. ValueError (naming the DBC) when it has not the protocol's shape."""
    dbc, out = Path(dbc), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    gen = _module(HERE / "generate_protocol.py", "_fw_generate_protocol")
    try:
        gen.generate(out, dbc)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{dbc}: {exc}") from None
    shutil.copyfile(dbc, out / "rhonn_id.dbc")   # the DBC the module embeds (pyrhonn.firmware.database)
    builder = _module(ROOT / "pyrhonn" / "_build.py", "_pyrhonn_build")
    name = f"_fwtwin_{_fingerprint(dbc.read_bytes())}"
    ffi = builder.make_fwapp_ffi(module=name, protocol_dir=out)
    return Path(ffi.compile(tmpdir=str(out)))


def load_twin(dbc: str | Path, cache_dir: str | Path | None = None) -> ModuleType:
    """The twin of ``dbc``, built into ``cache_dir`` (default: build_runner.py's cache) unless a build
    of exactly this DBC and these sources is there, and imported."""
    dbc = Path(dbc)
    try:
        text = dbc.read_bytes()
    except OSError as exc:
        raise ValueError(f"{dbc}: cannot read it: {exc.strerror or exc}") from None
    name = f"_fwtwin_{_fingerprint(text)}"
    if name in sys.modules:
        return sys.modules[name]
    runner = _module(FW / "linux" / "build_runner.py", "_fw_build_runner")
    done = runner.build_once(None if cache_dir is None else Path(cache_dir), name, "BUILT",
                             lambda work: (work / "BUILT").write_text(build(dbc, work).name))
    path = done.parent / done.read_text()
    loader = importlib.machinery.ExtensionFileLoader(name, str(path))
    spec = importlib.util.spec_from_file_location(name, path, loader=loader)
    assert spec is not None
    mod = importlib.util.module_from_spec(spec)
    loader.exec_module(mod)
    sys.modules[name] = mod
    return mod


def protocol(dbc: str | Path, cache_dir: str | Path | None = None) -> Any:
    """The :class:`pyrhonn.firmware.Protocol` of ``dbc`` with its twin (:func:`load_twin`)."""
    from pyrhonn.firmware import Protocol

    return Protocol.from_dbc(dbc, library=load_twin(dbc, cache_dir))


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dbc", type=Path)
    ap.add_argument("out_dir", type=Path, nargs="?", help="build here (default: load it from the cache)")
    args = ap.parse_args()
    try:
        print(build(args.dbc, args.out_dir) if args.out_dir else load_twin(args.dbc).__file__)
    except ValueError as exc:
        ap.error(str(exc))
