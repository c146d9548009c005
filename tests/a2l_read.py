"""An A2L read by pya2ldb in a child process, returned as plain data.

pya2ldb registers a SQLAlchemy listener on every Engine when it is imported
(it sets SQLite pragmas and a REGEXP function on each new connection), so an
import in the test process breaks every later PostgreSQL engine there (the
shared-study test of ``pyrhonn tune``). The tests read their A2L files
through this module instead, and never import pya2ldb themselves."""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

_CHILD = r"""
import json, sys
import pya2l
from pya2l import model
from pya2l.aml.ifdata_parser import IfDataParser

session = pya2l.import_a2l(sys.argv[1], in_memory=True, progress_bar=False, loglevel="ERROR")
try:
    module = session.query(model.Module).one()
    out = {
        "measurements": {m.name: [m.ecu_address.address, m.datatype] for m in session.query(model.Measurement)},
        "characteristics": {c.name: c.address for c in session.query(model.Characteristic)},
        "units": {c.name: c.unit for c in session.query(model.CompuMethod)},
        "project": session.query(model.Project).one().name,
        "if_data": IfDataParser(session).parse(module.if_data[0].raw),
    }
finally:
    session.close()
with open(sys.argv[2], "w", encoding="utf-8") as fh:  # not stdout: pya2ldb prints there
    json.dump(out, fh, default=str)
"""


def read_a2l(path: Path) -> dict[str, Any]:
    """The A2L's measurements (name: [address, datatype]), characteristics (name: address), units of
    its conversion methods, project name and parsed IF_DATA, as pya2ldb reads them; skips the test
    without pya2ldb."""
    if importlib.util.find_spec("pya2l") is None:
        pytest.skip("pya2ldb is not installed")
    target = Path(str(path) + ".json")
    res = subprocess.run([sys.executable, "-c", _CHILD, str(path), str(target)], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, f"pya2ldb could not read {path}:\n{res.stderr[-3000:]}"
    data: dict[str, Any] = json.loads(target.read_text(encoding="utf-8"))
    data["measurements"] = {k: tuple(v) for k, v in data["measurements"].items()}
    return data
