"""Build hook: compiles the C core into the two cffi extensions.

All project metadata lives in pyproject.toml; setuptools reads cffi_modules
only from setup(), so this file carries that one argument.
"""
from setuptools import setup

setup(cffi_modules=["pyrhonn/_build.py:ffi_f64", "pyrhonn/_build.py:ffi_f32", "pyrhonn/_build.py:ffi_fwapp"])
