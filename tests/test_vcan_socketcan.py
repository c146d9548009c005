"""SocketCAN on vcan0 (the VM tier: hil/vm/run_in_vm.py). Skipped where the
kernel has no vcan0, unless PYRHONN_REQUIRE_VCAN=1 (set inside the VM), in
which case a missing vcan0 fails."""
from __future__ import annotations

import can
import pytest

pytestmark = pytest.mark.vcan


def test_can_fd_frames_cross_vcan0_between_two_sockets(vcan0: str) -> None:
    with can.Bus(interface="socketcan", channel=vcan0, fd=True) as tx, \
            can.Bus(interface="socketcan", channel=vcan0, fd=True) as rx:
        for length in (0, 8, 12, 64):
            msg = can.Message(arbitration_id=0x123, data=bytes(range(length)), is_fd=True, is_extended_id=False,
                              bitrate_switch=True)
            tx.send(msg)
            got = rx.recv(2.0)
            assert got is not None, f"no frame of length {length} within 2 s"
            assert got.arbitration_id == 0x123 and bytes(got.data) == bytes(range(length)) and got.is_fd


def test_a_missing_interface_is_a_clear_error() -> None:
    with pytest.raises((OSError, can.CanError)):
        can.Bus(interface="socketcan", channel="vcan-does-not-exist", fd=True)
