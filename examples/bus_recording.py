"""A bus recording identified end to end: a DBC, a candump log, one command.

The plant (a damped oscillator driven through a motor command) is simulated
here and sent as CAN frames, as an ECU on a test bench would: a Sensors frame
every 10 ms with position and velocity (and a velocity-valid bit), and a
Command frame with the input. Some Sensors frames are lost and the velocity
sensor flags itself invalid for a while. python-can writes the candump log;
`pyrhonn identify --can-log` decodes it with the DBC, aligns the samples on
the Sensors clock, marks what is missing as not valid and identifies it.

    python examples/bus_recording.py [FOLDER]      (default: a new temporary folder)

Exits 1 if the identification is not as good as stated.
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import can
import cantools
import numpy as np

from pyrhonn.cli import main as pyrhonn

PERIOD = 0.01  # s, the Sensors frame's cycle
DBC = """VERSION ""

NS_ :

BS_:

BU_: PLANT CTRL

BO_ 256 Sensors: 8 PLANT
 SG_ Position : 0|24@1- (1e-05,0) [-80|80] "m" CTRL
 SG_ Velocity : 24|24@1- (1e-05,0) [-80|80] "m/s" CTRL
 SG_ VelocityValid : 48|1@1+ (1,0) [0|1] "" CTRL
 SG_ Counter : 56|8@1+ (1,0) [0|255] "" CTRL

BO_ 512 Command: 4 CTRL
 SG_ Torque : 0|16@1- (0.001,0) [-30|30] "N.m" PLANT
"""

CONFIG = """
format = "pyrhonn-config"
version = 1
n_states = 2
n_inputs = 1
state_names = ["position", "velocity"]
input_names = ["torque"]

[defaults]
activation = "bipolar"
beta = 1.0
p0 = 100.0
q = 1e-6
r = 1e-6
eta = 1.0

[[neurons]]
terms = ["x1", "x2"]
why = "the position integrates the velocity"

[[neurons]]
terms = ["x1", "x2", "S(x2)", "u1"]
why = "spring, damping, a saturating friction and the torque"

[bus]
sample_period = 0.01
clock = "Sensors"
counter = "Sensors.Counter"

[bus.signals]
position = "Sensors.Position"
velocity = "Sensors.Velocity"
torque = "Command.Torque"

[bus.valid]
velocity = "Sensors.VelocityValid"
"""

LOST = {500, 501, 502, 1700}      # Sensors frames that never reach the logger
VELOCITY_INVALID = range(1200, 1230)  # the velocity sensor flags its value invalid


def record(path: Path, db: cantools.database.Database, T: int = 3000) -> None:
    """Simulate the plant and write its frames as a candump log."""
    rng = np.random.default_rng(7)
    torque = np.repeat(rng.uniform(-1.0, 1.0, T // 40 + 1), 40)[:T]
    x = np.zeros(2)
    sensors, command = db.get_message_by_name("Sensors"), db.get_message_by_name("Command")
    with can.CanutilsLogWriter(str(path), channel="can0") as log:
        for k in range(T):
            t = 1_700_000_000.0 + k * PERIOD
            if k not in LOST:
                data = sensors.encode({"Position": x[0], "Velocity": x[1], "Counter": k % 256,
                                       "VelocityValid": 0 if k in VELOCITY_INVALID else 1})
                log.on_message_received(can.Message(timestamp=t, arbitration_id=sensors.frame_id,
                                                    is_extended_id=False, data=data))
            data = command.encode({"Torque": torque[k]})
            log.on_message_received(can.Message(timestamp=t + 0.002, arbitration_id=command.frame_id,
                                                is_extended_id=False, data=data))
            x = np.array([x[0] + PERIOD * x[1],
                          x[1] + PERIOD * (-4.0 * x[0] - 0.8 * x[1] - 0.5 * np.tanh(3.0 * x[1]) + 2.0 * torque[k])])


def main(folder: Path) -> int:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "plant.dbc").write_text(DBC)
    (folder / "plant.toml").write_text(CONFIG)
    db = cantools.database.load_file(str(folder / "plant.dbc"))
    record(folder / "run.log", db)
    code = pyrhonn(["identify", "--can-log", str(folder / "run.log"), "--dbc", str(folder / "plant.dbc"),
                    "--config", str(folder / "plant.toml"), "--out", str(folder / "id"), "--no-plots",
                    "--warmup", "500"])
    if code != 0:
        return code
    states = json.loads((folder / "id" / "metrics.json").read_text())["states"]
    print(f"outputs in {folder / 'id'}: samples.csv (the aligned samples), predictions.csv, metrics.json")
    # every lost frame and every flagged sample is a not-valid sample, none is invented or held
    missing = {"position": len(LOST), "velocity": len(LOST) + len(VELOCITY_INVALID)}
    ok = all(states[s]["invalid_samples"] == n and states[s]["rrse"] < 0.01 for s, n in missing.items())
    print("OK" if ok else "NOT AS STATED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp())))
