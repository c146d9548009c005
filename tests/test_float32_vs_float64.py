"""float32 against float64 on the paper's Example 1 setting (eq. 15 plant,
eq. 20 tuning with P(0) = 1e8 I): the gap between the two builds of the same
C core is reported and bounded."""
from __future__ import annotations

import numpy as np
import pytest

from pyrhonn import Identifier, presets
from pyrhonn.metrics import rmse
from pyrhonn.plants import oscillator

# Bounds, relative to each state's range: measured prediction gaps are <= 1.6e-6
# of the range and RMSE gaps <= 6e-7 (both T); the bounds leave a 60x margin.
MAX_PREDICTION_GAP = 1e-4
MAX_RMSE_GAP = 1e-4


@pytest.mark.parametrize("dt", [0.2, 0.02])
def test_float32_tracks_float64_on_example1(dt: float) -> None:
    traj = oscillator.simulate(dt=dt)
    runs = {}
    for dtype in ("float64", "float32"):
        ident = Identifier(presets.example1(dtype))
        runs[dtype] = ident.run(traj.X_meas.astype(dtype), traj.U.astype(dtype), traj.valid).astype(np.float64)
    scale = np.ptp(traj.X, axis=0)
    gap = np.max(np.abs(runs["float32"] - runs["float64"]), axis=0) / scale
    r64 = rmse(traj.X[1:], runs["float64"][:-1])
    r32 = rmse(traj.X[1:], runs["float32"][:-1])
    rgap = np.abs(r32 - r64) / r64
    print(f"\nT = {dt}: max |xhat32 - xhat64| / range per state = {np.array2string(gap, precision=2)}; "
          f"RMSE float64 = {np.array2string(r64, precision=5)}, relative RMSE gap = {np.array2string(rgap, precision=2)}")
    assert np.all(gap <= MAX_PREDICTION_GAP)
    assert np.all(rgap <= MAX_RMSE_GAP)
