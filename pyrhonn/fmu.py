"""Export an identifier as a Functional Mock-up Unit (FMI 3.0 or 2.0 co-simulation).

``export_fmu(cf, "plant.fmu", period=0.01)`` writes an FMU that embeds the C
core and the exported configuration (:mod:`pyrhonn.export`'s header), with
its C sources in ``sources/`` and a binary for this platform compiled when
the export runs with the system C compiler (``$CC``, else ``cc``). The FMI
headers come from the installed ``fmpy`` package (its ``c-code`` folder),
never from this repository. ``source=`` exports a trained Identifier, and
``warm_start=`` its running state too (the FMU continues its run, see
:func:`export_fmu`).

One communication step is one identifier step: at each communication point
``t`` the importer sets the measured states ``x(k)``, their valid flags and
the plant inputs ``u(k)``; ``doStep(t, T)`` learns ``x(k)`` and predicts
``x̂(k+1)``, which the outputs hold at ``t + T``. The step size must be the
sample period ``T`` (within ``1e-6 T``); any other is refused with an error
status and a log message. Variables (``<s>`` each state name, ``<u>`` each
input name of the config):

========================  =========  ===========================================
name                      causality  meaning
========================  =========  ===========================================
``<s>``                   input      measured state x_s(k) (Float64, discrete)
``<s>_valid``             input      the measurement is valid (Boolean; start true)
``<u>``                   input      plant input u(k) (Float64, discrete)
``<s>_hat``               output     prediction x̂_s(k+1) (x0 before the first step)
``<s>_nis``               output     e^2 / s of neuron s's last learning update
``<s>_trace_p``           output     trace of neuron s's covariance P
``<s>_refused``           output     learning updates refused so far (Int32)
``learning``              parameter  learning on (tunable Boolean)
``mode``                  parameter  0 = observer, 1 = simulator (tunable Int32)
``time``                  independent (FMI 3.0 only)
========================  =========  ===========================================

Modes: ``observer`` steps the measured states (learning from them while
``learning`` is on; a state whose valid flag is false is replaced by its
prediction, as in :meth:`pyrhonn.Identifier.step`); ``simulator`` steps
every state as not measured, so the network runs on its own predictions (a
free run, learning nothing; see :mod:`pyrhonn.simulation`). The variables
are Float64 whatever the precision; a float32 FMU rounds its inputs to
float32 and runs the core in float32.

A learning update the core refuses does not stop the simulation: the
sample is stepped again with learning frozen, ``<s>_refused`` counts it and
doStep returns a warning. A non-finite measured state (valid) or input is
an error naming the variable.
"""
from __future__ import annotations

import hashlib
import importlib.util
import math
import os
import platform
import shlex
import shutil
import subprocess
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from . import __version__, atomic
from .config import IdentifierConfig
from .configfile import ConfigFile
from .export import WarmSamples, _check_name, capacity_text, header_config, header_text
from .identifier import Identifier

__all__ = ["FMI_VERSIONS", "MODES", "FmuSettings", "check_for", "export_fmu", "fmi_headers", "variable_names"]

FMI_VERSIONS = (3, 2)
MODES = ("observer", "simulator")

# Value references: one block per kind of variable (pyrhonn_fmu_model.c's FMU_VR_*).
_VR_TIME, _VR_LEARNING, _VR_MODE = 0, 1, 2
_VR_X, _VR_VALID, _VR_U, _VR_XHAT, _VR_NIS, _VR_TRACE_P, _VR_REFUSED = 1000, 2000, 3000, 4000, 5000, 6000, 7000

#: The glue shipped with pyrhonn (package data), the model and one interface per FMI version.
_GLUE = Path(__file__).resolve().parent / "fmu_c"
_INTERFACE = {3: "pyrhonn_fmi3.c", 2: "pyrhonn_fmi2.c"}
#: The core's files an FMU compiles: its source and private header, its public headers.
_CORE_SOURCES = ("rhonn.c", "rhonn_internal.h")
_CORE_HEADERS = ("rhonn.h", "rhonn_capacity.h")
#: What a warm start adds: rhonn_warm_start and its header.
_WARM_FILES = ("rhonn_warm.c", "rhonn_warm.h")
#: The flags of the shipped binary: strict IEEE arithmetic (no contraction into
#: fused multiply-adds), as the Python extension and the firmware are built,
#: so the FMU computes the same bits as pyrhonn.Identifier.
_CFLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fno-fast-math", "-fPIC", "-shared", "-fvisibility=hidden")


@dataclass(frozen=True)
class FmuSettings:
    """How the FMU is built and what its parameters start at.

    ``period``: the sample period T in seconds (the only communication step
    size). ``fmi_version``: 3 (default) or 2. ``units``: state or input name
    -> unit (e.g. ``{"theta": "rad"}``), for those variables and their
    predictions. ``mode`` and ``learning``: the parameters' start values.
    ``model_identifier``: the C name of the FMU's binary and sources (a C
    identifier). ``compiler``: the C compiler command (default ``$CC``,
    else ``cc``).
    """

    period: float
    model_identifier: str
    fmi_version: int = 3
    units: Mapping[str, str] = field(default_factory=dict)
    mode: str = "observer"
    learning: bool = True
    compiler: str | None = None

    def __post_init__(self) -> None:
        if isinstance(self.period, bool) or not isinstance(self.period, (int, float)) or \
                not math.isfinite(self.period) or self.period <= 0:
            raise ValueError(f"period: expected a positive finite number of seconds, got {self.period!r}")
        _check_name(self.model_identifier)
        if self.model_identifier == "rhonn" or self.model_identifier.lower().startswith(("fmi", "fmu_", "pyrhonn_")):
            raise ValueError(f"name: {self.model_identifier!r} would clash with the FMU's own sources (the core's "
                             "rhonn.h, the FMI functions fmi*, the glue's fmu_* and pyrhonn_*); choose another")
        if self.fmi_version not in FMI_VERSIONS or isinstance(self.fmi_version, bool):
            raise ValueError(f"fmi_version: expected 3 or 2, got {self.fmi_version!r}")
        if self.mode not in MODES:
            raise ValueError(f"mode: expected one of {', '.join(MODES)}, got {self.mode!r}")
        if not isinstance(self.learning, bool):
            raise ValueError(f"learning: expected True or False, got {self.learning!r}")
        if not isinstance(self.units, Mapping):
            raise ValueError(f"units: expected a mapping of names to units, got {type(self.units).__name__}")
        for name, unit in self.units.items():
            if not isinstance(name, str):
                raise ValueError(f"units: expected state or input names as keys, got {name!r}")
            if not isinstance(unit, str) or not unit.strip() or not unit.isprintable():
                raise ValueError(f"units[{name!r}]: expected a non-empty printable unit, got {unit!r}")


def variable_names(cf: ConfigFile) -> dict[str, list[str]]:
    """The FMU's variable names by kind (``x``, ``valid``, ``u``, ``hat``,
    ``nis``, ``trace_p``, ``refused``), each in state (input) order;
    ValueError when two of them, or one and ``time``, ``learning`` or
    ``mode``, would be the same name."""
    s = list(cf.state_names)
    names = {"x": s, "valid": [f"{n}_valid" for n in s], "u": list(cf.input_names),
             "hat": [f"{n}_hat" for n in s], "nis": [f"{n}_nis" for n in s],
             "trace_p": [f"{n}_trace_p" for n in s], "refused": [f"{n}_refused" for n in s]}
    seen: dict[str, str] = {"time": "the FMU's time", "learning": "the learning parameter",
                            "mode": "the mode parameter"}
    for kind, group in names.items():
        for j, name in enumerate(group):
            what = f"the {kind} variable of {'input' if kind == 'u' else 'state'} {j + 1}"
            if name in seen:
                raise ValueError(f"state_names/input_names: the FMU variable {name!r} would be both {seen[name]} and "
                                 f"{what}; rename the state or input in the config")
            seen[name] = what
    return names


def fmi_headers(version: int) -> Path:
    """The folder of the FMI ``version`` headers that the installed fmpy
    package ships (``fmpy/c-code``); ValueError when fmpy is missing."""
    spec = importlib.util.find_spec("fmpy")
    if spec is None or spec.origin is None:
        raise ValueError("fmpy: not installed; the FMI headers come from it (pip install fmpy, or pyrhonn[fmu])")
    folder = Path(spec.origin).parent / "c-code"
    header = "fmi3Functions.h" if version == 3 else "fmi2Functions.h"
    if not (folder / header).is_file():
        raise ValueError(f"fmpy: {header} is not in {folder} (a newer or damaged fmpy?)")
    return folder


def _core_file(name: str) -> Path:
    """A core file: the source tree's csrc, else the copy an installed pyrhonn ships (setup.py)."""
    here = Path(__file__).resolve().parent
    for folder in (here.parent / "csrc" / "src", here.parent / "csrc" / "include", here / "core_src",
                   here / "core_include"):
        if (folder / name).is_file():
            return folder / name
    raise ValueError(f"the core's {name} is not installed with pyrhonn (reinstall pyrhonn)")


def _platform_folder(version: int) -> str:
    system, machine = platform.system(), platform.machine().lower()
    if system != "Linux" or machine not in ("x86_64", "amd64", "aarch64", "arm64"):
        raise ValueError(f"binaries: building on {system} {machine} is not supported (Linux x86_64 or aarch64)")
    arch = "x86_64" if machine in ("x86_64", "amd64") else "aarch64"
    if version == 3:
        return f"{arch}-linux"
    if arch != "x86_64":
        raise ValueError(f"binaries: FMI 2.0 names no {arch} Linux platform; export FMI 3.0")
    return "linux64"


def _real(v: float, dtype: str) -> str:
    """The shortest decimal that reads back as the same float64 (float32 values are exact in it)."""
    return repr(float(np.float32(v)) if dtype == "float32" else float(v))


@dataclass(frozen=True)
class _Variable:
    name: str
    vr: int
    type: str           # "Float64", "Boolean", "Int32" (FMI 3 names)
    causality: str
    variability: str
    description: str
    start: str | None = None
    unit: str | None = None
    initial: str | None = None
    extra: tuple[tuple[str, str], ...] = ()


def check_for(cf: ConfigFile, settings: FmuSettings) -> dict[str, list[str]]:
    """What an FMU of ``cf`` with ``settings`` cannot express, as a
    ValueError naming the field (a unit for a name that is not a state or
    input, variable names that clash); else its :func:`variable_names`."""
    names = variable_names(cf)
    unknown = sorted(set(settings.units) - set(cf.state_names) - set(cf.input_names))
    if unknown:
        raise ValueError(f"units: {', '.join(unknown)}: not a state or input of the config (states: "
                         f"{', '.join(cf.state_names)}; inputs: {', '.join(cf.input_names) or 'none'})")
    return names


def _variables(cf: ConfigFile, cfg: IdentifierConfig, s: FmuSettings) -> list[_Variable]:
    names = check_for(cf, s)
    x0 = cfg.x0_vector()
    out: list[_Variable] = []
    if s.fmi_version == 3:
        out.append(_Variable("time", _VR_TIME, "Float64", "independent", "continuous", "simulation time"))
    out.append(_Variable("learning", _VR_LEARNING, "Boolean", "parameter", "tunable",
                         "learning on: observer mode learns from the measured states",
                         "true" if s.learning else "false"))
    out.append(_Variable("mode", _VR_MODE, "Int32", "parameter", "tunable",
                         "0 = observer (steps the measured states), 1 = simulator (free run on its own predictions)",
                         str(MODES.index(s.mode)), extra=(("min", "0"), ("max", "1"))))
    for j, name in enumerate(cf.state_names):
        out.append(_Variable(name, _VR_X + j, "Float64", "input", "discrete", f"measured state {name}",
                             _real(x0[j], cfg.dtype), s.units.get(name)))
    for j, name in enumerate(cf.state_names):
        out.append(_Variable(names["valid"][j], _VR_VALID + j, "Boolean", "input", "discrete",
                             f"{name} is measured (false: a dropout, replaced by its prediction)", "true"))
    for j, name in enumerate(cf.input_names):
        out.append(_Variable(name, _VR_U + j, "Float64", "input", "discrete", f"plant input {name}", "0.0",
                             s.units.get(name)))
    outputs = (("hat", _VR_XHAT, "Float64", "prediction of {} at the next sample", True),
               ("nis", _VR_NIS, "Float64", "normalised innovation squared of {}'s last learning update", False),
               ("trace_p", _VR_TRACE_P, "Float64", "trace of {}'s covariance P", False),
               ("refused", _VR_REFUSED, "Int32", "learning updates of {} refused by the core", False))
    for kind, base, typ, text, with_unit in outputs:
        for j, name in enumerate(cf.state_names):
            out.append(_Variable(names[kind][j], base + j, typ, "output", "discrete", text.format(name),
                                 unit=s.units.get(name) if with_unit else None, initial="calculated"))
    return out


_FMI2_TYPE = {"Float64": "Real", "Boolean": "Boolean", "Int32": "Integer"}


def _xml(root: ET.Element) -> bytes:
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"


def _unit_definitions(root: ET.Element, variables: list[_Variable]) -> None:
    units = sorted({v.unit for v in variables if v.unit})
    if units:
        defs = ET.SubElement(root, "UnitDefinitions")
        for unit in units:
            ET.SubElement(defs, "Unit", name=unit)


def _log_categories(root: ET.Element) -> None:
    cats = ET.SubElement(root, "LogCategories")
    for name, text in (("logStatusWarning", "a learning update refused (the sample stepped with learning frozen)"),
                       ("logStatusError", "a refused call: bad step size or time, a non-finite input, bad mode")):
        ET.SubElement(cats, "Category", name=name, description=text)


def _model_description(cf: ConfigFile, cfg: IdentifierConfig, s: FmuSettings, variables: list[_Variable],
                       token: str, sources: list[str]) -> bytes:
    common = {"modelName": s.model_identifier,
              "description": f"pyrhonn identifier: {cfg.n_states} state{'s' * (cfg.n_states != 1)}, "
                             f"{cfg.n_inputs} input{'s' * (cfg.n_inputs != 1)}, {cfg.dtype}, "
                             f"sample period {s.period!r} s",
              "generationTool": f"pyrhonn {__version__}", "variableNamingConvention": "flat"}
    if s.fmi_version == 3:
        root = ET.Element("fmiModelDescription", {"fmiVersion": "3.0", "instantiationToken": token, **common})
        ET.SubElement(root, "CoSimulation", modelIdentifier=s.model_identifier,
                      canHandleVariableCommunicationStepSize="false", fixedInternalStepSize=repr(float(s.period)),
                      canBeInstantiatedOnlyOncePerProcess="false", canGetAndSetFMUState="false",
                      canSerializeFMUState="false", hasEventMode="false")
    else:
        root = ET.Element("fmiModelDescription", {"fmiVersion": "2.0", "guid": token, "numberOfEventIndicators": "0",
                                                  **common})
        cs = ET.SubElement(root, "CoSimulation", modelIdentifier=s.model_identifier,
                           canHandleVariableCommunicationStepSize="false", canBeInstantiatedOnlyOncePerProcess="false",
                           canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate="false",
                           canSerializeFMUstate="false")
        files = ET.SubElement(cs, "SourceFiles")
        for name in sources:
            ET.SubElement(files, "File", name=name)
    _unit_definitions(root, variables)
    _log_categories(root)
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stepSize=repr(float(s.period)))
    mv = ET.SubElement(root, "ModelVariables")
    index: dict[int, int] = {}
    for k, v in enumerate(variables):
        attrs = {"name": v.name, "valueReference": str(v.vr), "description": v.description, "causality": v.causality,
                 "variability": v.variability}
        if v.initial:
            attrs["initial"] = v.initial
        typed = {**({"unit": v.unit} if v.unit else {}), **dict(v.extra),
                 **({"start": v.start} if v.start is not None else {})}
        if s.fmi_version == 3:
            ET.SubElement(mv, v.type, {**attrs, **typed})
        else:
            sv = ET.SubElement(mv, "ScalarVariable", attrs)
            ET.SubElement(sv, _FMI2_TYPE[v.type], typed)
            index[v.vr] = k + 1
    ms = ET.SubElement(root, "ModelStructure")
    outputs = [v for v in variables if v.causality == "output"]
    if s.fmi_version == 3:
        for v in outputs:
            ET.SubElement(ms, "Output", valueReference=str(v.vr))
        for v in outputs:
            ET.SubElement(ms, "InitialUnknown", valueReference=str(v.vr))
    else:
        for tag in ("Outputs", "InitialUnknowns"):
            group = ET.SubElement(ms, tag)
            for v in outputs:
                ET.SubElement(group, "Unknown", index=str(index[v.vr]))
    return _xml(root)


def _build_description(s: FmuSettings, unity: str) -> bytes:
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    bc = ET.SubElement(root, "BuildConfiguration", modelIdentifier=s.model_identifier,
                       description="one translation unit: the core, the configuration and the FMI 3.0 interface")
    fs = ET.SubElement(bc, "SourceFileSet", language="C99", compilerOptions="-ffp-contract=off -fno-fast-math")
    ET.SubElement(fs, "SourceFile", name=unity)
    ET.SubElement(bc, "Library", name="m", external="true", description="the C math library")
    return _xml(root)


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _model_header(cf: ConfigFile, cfg: IdentifierConfig, s: FmuSettings, token: str, warm: bool) -> str:
    ident = s.model_identifier
    names = ", ".join(_c_string(n) for n in cf.state_names)
    inputs = ", ".join(_c_string(n) for n in cf.input_names) or '""'
    return "\n".join([
        f"/* Generated by pyrhonn: the co-simulation model of FMU {ident!r}. Do not edit: export again. */",
        f"#define FMU_CONFIG {ident}",
        *([f"#define FMU_WARM {ident}_warm /* started (and reset) from this running state */"] if warm else []),
        f"#define FMU_N {cfg.n_states}u",
        f"#define FMU_M {cfg.n_inputs}u",
        f"#define FMU_PERIOD {float(s.period).hex()} /* {s.period!r} s */",
        f"#define FMU_LEARNING0 {int(s.learning)}",
        f"#define FMU_MODE0 {MODES.index(s.mode)} /* {s.mode} */",
        f"#define FMU_TOKEN {_c_string(token)}",
        f"static const char *const fmu_state_names[{cfg.n_states}] = {{{names}}};",
        f"static const char *const fmu_input_names[{max(cfg.n_inputs, 1)}] = {{{inputs}}};",
        "",
    ])


def _unity_source(cfg: IdentifierConfig, s: FmuSettings, warm: bool) -> str:
    ident = s.model_identifier
    return "\n".join([
        f"/* Generated by pyrhonn: FMU {ident!r} as one translation unit (FMI {s.fmi_version}.0 co-simulation).",
        " * Build it as C99 with strict IEEE arithmetic (GCC, Clang: -ffp-contract=off -fno-fast-math) to compute",
        " * the bits pyrhonn.Identifier computes; link the C math library. */",
        *(["#define RHONN_SINGLE 1"] if cfg.dtype == "float32" else []),
        f'#define RHONN_USER_CAPACITY "{ident}_capacity.h"',
        '#include "rhonn.c"',
        *(['#include "rhonn_warm.c"'] if warm else []),
        f'#include "{ident}.h"',
        f'#include "{ident}_model.h"',
        '#include "pyrhonn_fmu_model.c"',
        f'#include "{_INTERFACE[s.fmi_version]}"',
        "",
    ])


def _compile(cc: str, sources: Path, headers: Path, unity: str, out: Path) -> None:
    cmd = [*shlex.split(cc), *_CFLAGS, f"-I{sources}", f"-I{headers}", str(sources / unity), "-o", str(out), "-lm"]
    try:
        build = subprocess.run(cmd, capture_output=True, text=True)
    except OSError as exc:
        raise ValueError(f"compiler: {cc!r} could not run: {exc}") from None
    if build.returncode != 0:
        raise ValueError(f"compiler: {cc} failed on the FMU's sources: {build.stderr.strip()[:800]}")


def export_fmu(cf: ConfigFile, path: str | Path, settings: FmuSettings, *,
               source: Identifier | IdentifierConfig | None = None, warm_start: WarmSamples | None = None) -> Path:
    """Write the FMU of ``cf`` to ``path`` and return ``path``. ``source``
    replaces ``cf``'s configuration (the names stay ``cf``'s): an
    Identifier, e.g. trained on a recording (its weights and covariances
    become the FMU's starting point), or a config. ``warm_start``: the
    samples (X, U, valid) an Identifier ``source`` last stepped on; the FMU
    then starts from its running state and continues its run bit for bit
    (:func:`pyrhonn.export.export_header`'s warm start; a reset returns to
    that state). The file is replaced whole (:mod:`pyrhonn.atomic`); on any
    error nothing is written. ValueError naming the field for bad arguments,
    a missing compiler, fmpy or a platform without a binary folder."""
    if not isinstance(cf, ConfigFile):
        raise ValueError(f"cf: expected a ConfigFile, got {type(cf).__name__}")
    if not isinstance(settings, FmuSettings):
        raise ValueError(f"settings: expected FmuSettings, got {type(settings).__name__}")
    if source is not None and not isinstance(source, (Identifier, IdentifierConfig)):
        raise ValueError(f"source: expected an Identifier or IdentifierConfig, got {type(source).__name__}")
    cfg = cf.config if source is None else header_config(source, warm_start is not None)
    if (cfg.n_states, cfg.n_inputs) != (cf.config.n_states, cf.config.n_inputs):
        raise ValueError(f"source: {cfg.n_states} states and {cfg.n_inputs} inputs, the names are for "
                         f"{cf.config.n_states} and {cf.config.n_inputs}")
    path = Path(path)
    if path.suffix != ".fmu":
        raise ValueError(f"path {str(path)!r}: expected a file name ending in .fmu")
    if not path.parent.is_dir():
        raise ValueError(f"path {str(path)!r}: the folder {str(path.parent)!r} does not exist")
    if path.is_dir():
        raise ValueError(f"path {str(path)!r}: is a folder")
    s = settings
    variables = _variables(cf, cfg, s)
    headers = fmi_headers(s.fmi_version)
    binaries = f"binaries/{_platform_folder(s.fmi_version)}"
    cc = s.compiler or os.environ.get("CC") or "cc"
    if not cc.strip() or shutil.which(shlex.split(cc)[0]) is None:
        raise ValueError(f"compiler: {cc!r} not found; the FMU's binary is compiled when it is exported (install a C "
                         "compiler, e.g. gcc, or set CC)")
    ident = s.model_identifier
    config_h = header_text(cfg if source is None else source, ident, warm_start=warm_start)
    core = (*_CORE_SOURCES, *_CORE_HEADERS) + (_WARM_FILES if warm_start is not None else ())
    files: dict[str, bytes] = {
        f"sources/{ident}.h": config_h.encode(),
        f"sources/{ident}_capacity.h": capacity_text(cfg, ident, "an FMU build").encode(),
    }
    for name in core:
        files[f"sources/{name}"] = _core_file(name).read_bytes()
    for name in ("pyrhonn_fmu_model.c", _INTERFACE[s.fmi_version]):
        files[f"sources/{name}"] = (_GLUE / name).read_bytes()
    # The token names this build: the configuration, the variables and the glue.
    digest = hashlib.sha256(config_h.encode() + repr((variables, s.period, s.fmi_version)).encode()
                            + b"".join(files[f"sources/{n}"] for n in ("pyrhonn_fmu_model.c",
                                                                      _INTERFACE[s.fmi_version])))
    token = "{" + str(uuid.UUID(bytes=digest.digest()[:16], version=5)) + "}"
    unity = f"{ident}_fmu.c"
    files[f"sources/{ident}_model.h"] = _model_header(cf, cfg, s, token, warm_start is not None).encode()
    files[f"sources/{unity}"] = _unity_source(cfg, s, warm_start is not None).encode()
    if s.fmi_version == 3:
        files["sources/buildDescription.xml"] = _build_description(s, unity)
    files["modelDescription.xml"] = _model_description(cf, cfg, s, variables, token, [unity])
    with ExitStack() as stack:
        try:  # the temporary file first: a folder that cannot be written fails before the build
            out = stack.enter_context(atomic.replacing(path, "wb"))
        except OSError as exc:
            raise ValueError(f"path {str(path)!r}: cannot be written ({exc.strerror or exc})") from None
        tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="pyrhonn-fmu-")))
        (tmp / "sources").mkdir()
        for name, data in files.items():
            (tmp / name).write_bytes(data)
        _compile(cc, tmp / "sources", headers, unity, tmp / f"{ident}.so")
        files[f"{binaries}/{ident}.so"] = (tmp / f"{ident}.so").read_bytes()
        with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
            for name in sorted(files):
                info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = (0o755 if name.endswith(".so") else 0o644) << 16
                zf.writestr(info, files[name])
    return path
