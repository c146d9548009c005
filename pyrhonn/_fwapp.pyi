"""Types of the cffi extension pyrhonn._fwapp, built by pyrhonn/_build.py."""
from typing import Any

ffi: Any
lib: Any
