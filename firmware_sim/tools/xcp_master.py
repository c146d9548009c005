"""pyxcp as the master of the runner's XCP slave (fw_xcp.h): the pieces a
test or a bench needs beside pyxcp itself.

- :func:`key`: the slave's seed & key, AES-CMAC of the seed with the
  firmware's command key (pyxcp's ``seed_n_key_function``);
- :class:`Samples`: a DAQ policy keeping every sample as a dict by
  measurement name (pyxcp packs the ODTs by address, so a sample's values
  follow the list's headers, not the order they were given in);
- :func:`udp_drops`: the kernel's count of datagrams a local UDP socket's
  receive queue dropped, which tells a DAQ packet lost by the master from
  one the slave never sent;
- :func:`replay`: the rig's Measurements sent one at a time over a
  python-can bus, each once the previous one was answered, so the slave
  runs one step per frame whatever the machine's speed.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import can

from cryptography.hazmat.primitives.ciphers import algorithms
from cryptography.hazmat.primitives.cmac import CMAC
from pyxcp.daq_stim import DaqList, DaqOnlinePolicy

from pyrhonn.firmware import TEST_KEY


def key(resource: int, seed: bytes, secret: bytes | None = None) -> bytes:
    """UNLOCK's key for ``seed``: AES-CMAC(secret, seed), 16 bytes; the
    secret defaults to the simulations' public test key. ``resource`` is
    pyxcp's argument, not part of the key."""
    secret = TEST_KEY if secret is None else secret
    if secret is None or len(secret) != 16:
        raise ValueError("secret: a 16-byte AES key is needed (this build has no test key)")
    mac = CMAC(algorithms.AES(secret))
    mac.update(bytes(seed))
    return mac.finalize()


class Samples(DaqOnlinePolicy):
    """Every DAQ sample: (list index, slave timestamp in ns, {name: value})."""

    def __init__(self, lists: list[DaqList]) -> None:
        super().__init__(lists)
        self.rows: list[tuple[int, int, dict[str, float]]] = []

    def on_daq_list(self, daq_list: int, timestamp0: int, timestamp1: int, payload: list) -> None:
        names = [h[0] for h in self.daq_lists[daq_list].headers]
        self.rows.append((daq_list, timestamp1, dict(zip(names, payload))))


def udp_drops(port: int) -> int:
    """Datagrams dropped so far by the IPv4 UDP socket bound to
    127.0.0.1:``port`` (/proc/net/udp's drops); 0 when there is none."""
    want = f"0100007F:{port:04X}"
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        fields = line.split()
        if len(fields) > 1 and fields[1] == want:
            return int(fields[-1])
    return 0


def replay(bus: can.BusABC, frames: Sequence[can.Message], answer_id: int, timeout: float = 2.0) -> int:
    """Send ``frames`` one by one, each once the previous one's answer (a
    frame with ``answer_id``) came back or ``timeout`` seconds passed; the
    number answered."""
    answered = 0
    for frame in frames:
        bus.send(frame)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = bus.recv(timeout=min(0.5, timeout))
            if msg is not None and msg.arbitration_id == answer_id:
                answered += 1
                break
    return answered
