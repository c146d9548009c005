"""Who may command the firmware: the SecOC-style authentication of Control and
WeightLoad (firmware_sim/app/fw_secoc.h, fw_aes_cmac.h) through the Python twin.

- The firmware's AES-128-CMAC equals the ``cryptography`` package's, for any
  key and message (hypothesis), and so does the secured trailer the rig's
  :class:`pyrhonn.firmware.SecOCSender` writes.
- A frame secured by an independent implementation (``cryptography``, the
  layout as documented) is accepted: the documentation is the protocol.
- A forged MAC, a replayed frame, a stale freshness value, a frame of the
  wrong length are each rejected, counted, not answered, and leave the
  identifier bit for bit unchanged; a correctly authenticated command works.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

can = pytest.importorskip("can")
pytest.importorskip("cantools")
cmac_mod = pytest.importorskip("cryptography.hazmat.primitives.cmac")
from cryptography.hazmat.primitives.ciphers import algorithms  # noqa: E402

from pyrhonn import firmware  # noqa: E402
from pyrhonn.configfile import load_shipped  # noqa: E402
from pyrhonn.firmware import FirmwareApp, SecOCSender  # noqa: E402

ffi, lib = firmware._ffi, firmware._lib
DB = firmware.database()
CONFIG = load_shipped("firmware-lim").config.replace(dtype="float32")
CONTROL, WEIGHTS = DB.get_message_by_name("Control"), DB.get_message_by_name("WeightLoad")
FAST = settings(max_examples=300, deadline=None)


def _cmac(key: bytes, msg: bytes) -> bytes:
    c = cmac_mod.CMAC(algorithms.AES(key))
    c.update(msg)
    return c.finalize()


def _c_cmac(key: bytes, msg: bytes) -> bytes:
    tag = ffi.new("uint8_t[16]")
    assert lib.fw_aes128_cmac(key, msg if msg else ffi.NULL, len(msg), tag) == lib.FW_OK
    return bytes(tag)


def _independent_secure(frame_id: int, authentic: bytes, freshness: int, key: bytes = firmware.TEST_KEY) -> bytes:
    """The secured PDU as docs/firmware-protocol.md describes it, built without
    the firmware's code: authentic | FV low 32 bits LE | CMAC[:8] over
    DataId BE | authentic | FV 64 bits BE."""
    mac = _cmac(key, frame_id.to_bytes(2, "big") + authentic + freshness.to_bytes(8, "big"))[:8]
    return authentic + (freshness & 0xFFFFFFFF).to_bytes(4, "little") + mac


def _warm_app() -> tuple[FirmwareApp, bytes]:
    app = FirmwareApp(None, CONFIG, host_clock=False)
    rng = np.random.default_rng(3)
    for seq in range(30):
        msg = firmware.measurement_message(seq, rng.uniform(-0.5, 0.5, 6), rng.uniform(-100, 100, 2))
        app.handle(msg)
    assert app.counters["measurements"] == 30
    return app, app.identifier_bytes()


def test_the_twin_is_built_with_authentication_on_and_the_public_test_key() -> None:
    assert firmware.SECOC_ENABLED
    assert firmware.TEST_KEY == b"pyrhonn-TEST-key"
    assert CONTROL.length == 16 and WEIGHTS.length == 64 and firmware.WEIGHTS_PER_FRAME == 12
    assert DB.version == "rhonn_id 2.2"


@FAST
@given(key=st.binary(min_size=16, max_size=16), msg=st.binary(min_size=0, max_size=100))
def test_firmware_cmac_equals_the_cryptography_package(key: bytes, msg: bytes) -> None:
    assert _c_cmac(key, msg) == _cmac(key, msg)


@FAST
@given(key=st.binary(min_size=16, max_size=16), freshness=st.integers(0, 2 ** 64 - 2),
       command=st.integers(0, 255), token=st.integers(0, 255))
def test_the_senders_trailer_is_the_documented_layout(key: bytes, freshness: int, command: int, token: int) -> None:
    tx = SecOCSender(key, freshness=freshness)
    msg = firmware.control_message(command, token, sender=tx)
    assert tx.freshness == freshness + 1
    authentic = bytes([command, token, 0, 0])
    assert bytes(msg.data) == _independent_secure(0x110, authentic, freshness + 1, key)


def test_a_command_secured_by_an_independent_implementation_is_accepted() -> None:
    app, _ = _warm_app()
    frame = _independent_secure(0x110, bytes([firmware.COMMANDS["LearningOff"], 42, 0, 0]), 7)
    (ack,) = app.handle_frame(0x110, frame)
    assert app.last_status == "FW_OK" and app.freshness == 7
    d = DB.decode_message("ControlAck", bytes(ack.data), decode_choices=False)
    assert (d["Command"], d["Token"], d["Result"]) == (2, 42, 0)
    # and a WeightLoad, inside a transfer opened by the library's sender
    tx = SecOCSender(firmware.TEST_KEY, freshness=7)
    app.handle(firmware.control_message("WeightsBegin", 1, sender=tx))
    values = {"Neuron": 0, "First": 0, "Count": 1, **{f"W{k:02d}": 0.25 if k == 0 else 0.0 for k in range(12)},
              "Freshness": 0, "Mac": 0}
    authentic = WEIGHTS.encode(values)[:52]
    app.handle_frame(0x120, _independent_secure(0x120, authentic, 9))
    assert app.last_status == "FW_OK" and app.counters["weight_chunks"] == 1


def _reference_verdict(latest: int, fv: int) -> str:
    """AUTOSAR's reconstruction with the acceptance window, written out: the
    received low 32 bits replace the last accepted value's, the high half
    carries when they are not greater; then newer by at most the window, and
    the MAC (over the sender's own full value) must match the rebuilt one."""
    low, mask = fv & 0xFFFFFFFF, 0xFFFFFFFF
    cand = (latest & ~mask & (2 ** 64 - 1)) | low
    if low <= latest & mask:
        if latest >> 32 == mask:
            return "FW_E_FRESHNESS"
        cand += 2 ** 32
    if cand - latest > int(lib.FW_SECOC_ACCEPTANCE_WINDOW):
        return "FW_E_FRESHNESS"
    return "FW_OK" if cand == fv else "FW_E_AUTH"


@FAST
@given(latest=st.integers(0, 2 ** 64 - 1),
       delta=st.one_of(st.integers(-70_000, 70_000), st.integers(-2 ** 40, 2 ** 40),
                       st.sampled_from([2 ** 32, -2 ** 32, 2 ** 32 + 1, -2 ** 32 + 1, 65_536, 65_537])))
def test_freshness_is_rebuilt_and_windowed_as_autosar_does(latest: int, delta: int) -> None:
    fv = latest + delta
    if not 0 <= fv < 2 ** 64:
        fv = (latest - delta) % 2 ** 64
    k = ffi.new("fw_cmac_key *")
    lib.fw_cmac_init(k, firmware.TEST_KEY)
    pdu = ffi.new("uint8_t[16]", bytes([3, 1, 0, 0]) + bytes(12))
    assert lib.fw_secoc_protect(k, 0x110, pdu, 16, fv) == lib.FW_OK
    held = ffi.new("uint64_t *", latest)
    got = firmware.status_name(lib.fw_secoc_verify(k, 0x110, pdu, 16, held))
    assert got == _reference_verdict(latest, fv)
    assert held[0] == (fv if got == "FW_OK" else latest)
    if got == "FW_OK":  # and the very same frame is a replay now
        assert firmware.status_name(lib.fw_secoc_verify(k, 0x110, pdu, 16, held)) == "FW_E_FRESHNESS"


def _refused(app: FirmwareApp, before: bytes, data: bytes, status: str, can_id: int = 0x110) -> None:
    fv = app.freshness
    replies = app.handle_frame(can_id, data)
    assert app.last_status == status
    assert replies == []                      # not answered
    assert app.identifier_bytes() == before   # the identifier, bit for bit
    assert app.freshness == fv


def test_forged_replayed_stale_and_short_commands_are_rejected_counted_and_change_nothing() -> None:
    app, before = _warm_app()
    tx = SecOCSender(firmware.TEST_KEY)
    reset = bytearray(firmware.control_message("Reset", 1, sender=tx).data)
    reset[-1] ^= 0x01                                                              # forged MAC
    _refused(app, before, bytes(reset), "FW_E_AUTH")
    unsigned = CONTROL.encode({"Command": 2, "Token": 0, "Freshness": 2, "Mac": 0})
    _refused(app, before, unsigned, "FW_E_AUTH")                                   # no MAC at all
    chunk = bytearray(firmware.weight_load_messages([np.ones(2)], sender=tx)[0].data)
    chunk[4] ^= 0x40                                                               # a weight changed
    _refused(app, before, bytes(chunk), "FW_E_AUTH", 0x120)
    _refused(app, before, bytes(firmware.control_message("Reset", 1, sender=tx).data)[:15], "FW_E_LENGTH")
    _refused(app, before, bytes(firmware.control_message("Reset", 1, sender=tx).data)[:8], "FW_E_LENGTH")
    far = SecOCSender(firmware.TEST_KEY, freshness=int(lib.FW_SECOC_ACCEPTANCE_WINDOW) + 10)
    _refused(app, before, bytes(firmware.control_message("Reset", 1, sender=far).data), "FW_E_FRESHNESS")
    c = app.counters
    assert (c["rejected_auth"], c["rejected_length"], c["rejected_freshness"]) == (3, 2, 1)
    assert c["commands"] == 0 and c["weight_chunks"] == 0 and c["rejected"] == 6

    # authenticated: LearningOff works and is answered
    off = firmware.control_message("LearningOff", 5, sender=tx)
    (ack,) = app.handle(off)
    assert app.last_status == "FW_OK" and app.counters["commands"] == 1
    assert DB.decode_message("ControlAck", bytes(ack.data), decode_choices=False)["Result"] == 0
    after = app.identifier_bytes()
    assert after != before                                                         # learning is off now
    _refused(app, after, bytes(off.data), "FW_E_FRESHNESS")                        # replayed
    old = SecOCSender(firmware.TEST_KEY, freshness=1)                              # stale: freshness 2 < 7
    _refused(app, after, bytes(firmware.control_message("Reset", 6, sender=old).data), "FW_E_FRESHNESS")
    assert app.counters["rejected_freshness"] == 3 and app.counters["last_reject"] == int(lib.FW_E_FRESHNESS)
    (ack,) = app.handle(firmware.control_message("Reset", 7, sender=tx))          # and the rig goes on
    assert app.last_status == "FW_OK"


@settings(max_examples=200, deadline=None)
@given(bit=st.integers(0, 16 * 8 - 1), command=st.sampled_from(sorted(firmware.COMMANDS.values())))
def test_any_flipped_bit_of_a_secured_command_is_rejected(bit: int, command: int) -> None:
    app = FirmwareApp(None, CONFIG, host_clock=False)
    before = app.identifier_bytes()
    data = bytearray(firmware.control_message(command, 3, sender=SecOCSender(firmware.TEST_KEY)).data)
    data[bit // 8] ^= 1 << (bit % 8)
    assert app.handle_frame(0x110, bytes(data)) == []
    assert app.last_status in ("FW_E_AUTH", "FW_E_FRESHNESS")
    assert app.identifier_bytes() == before and app.counters["commands"] == 0


def test_sender_refuses_bad_keys_and_counters() -> None:
    with pytest.raises(ValueError, match="key: expected 16 bytes"):
        SecOCSender(b"short")
    with pytest.raises(ValueError, match="key: expected 16 bytes"):
        SecOCSender("pyrhonn-TEST-key")  # type: ignore[arg-type]
    for bad in (-1, 2 ** 64 - 1, 1.5, True):
        with pytest.raises(ValueError, match="freshness"):
            SecOCSender(firmware.TEST_KEY, freshness=bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="sender: expected a SecOCSender"):
        firmware.control_message("Reset", sender=None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="frame_id: expected an 11-bit"):
        SecOCSender(firmware.TEST_KEY).protect(0x800, bytes(16))
    with pytest.raises(ValueError, match="cannot carry"):
        SecOCSender(firmware.TEST_KEY).protect(0x110, bytes(11))
    tx = SecOCSender(firmware.TEST_KEY, freshness=2 ** 64 - 2)
    firmware.control_message("Reset", sender=tx)
    with pytest.raises(ValueError, match="spent"):
        firmware.control_message("Reset", sender=tx)


def test_a_replayed_weight_chunk_is_rejected_and_stages_nothing() -> None:
    app = FirmwareApp(None, CONFIG, host_clock=False)
    tx = SecOCSender(firmware.TEST_KEY)
    (ack,) = app.handle(firmware.control_message("WeightsBegin", 1, sender=tx))
    total = DB.decode_message("ControlAck", bytes(ack.data), decode_choices=False)["Missing"]
    L0 = CONFIG.neurons[0].n_terms
    (chunk,) = firmware.weight_load_messages([np.full(L0, 0.5, dtype=np.float32)], sender=tx)
    assert app.handle(chunk) == [] and app.last_status == "FW_OK"
    assert app.handle(chunk) == [] and app.last_status == "FW_E_FRESHNESS"
    assert app.counters["weight_chunks"] == 1 and app.counters["rejected_freshness"] == 1
    (ack,) = app.handle(firmware.control_message("WeightsCommit", 2, sender=tx))
    d = DB.decode_message("ControlAck", bytes(ack.data), decode_choices=False)
    assert d["Result"] == int(lib.FW_E_WEIGHTS) and d["Missing"] == total - L0
