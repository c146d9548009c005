"""Shared test settings: a hypothesis profile for CI (fixed seed, derandomised
so a red run can be reproduced) and one for local runs."""
from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("dev", print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")
