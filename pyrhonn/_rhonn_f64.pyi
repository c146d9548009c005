"""Types of the cffi extension pyrhonn._rhonn_f64, built by pyrhonn/_build.py."""
from typing import Any

ffi: Any
lib: Any
