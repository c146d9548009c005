"""Types of the cffi extension pyrhonn._csvtext (the CSV text codec), built by pyrhonn/_build.py."""
from typing import Any

ffi: Any
lib: Any
