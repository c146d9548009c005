"""A message's frames decoded at once with numpy give exactly what cantools gives frame by frame: the same
values bit for bit (Intel and Motorola signals at any start bit, 1..64 bits, signed and unsigned, IEEE
floats, integer and real scales and offsets, large ones), the same frames refused (a payload shorter than
the message); what it does not decode itself (a multiplexed message) goes to cantools."""
from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

cantools = pytest.importorskip("cantools")

from cantools.database.can import Message, Signal  # noqa: E402
from cantools.database.conversion import BaseConversion  # noqa: E402

from pyrhonn.framedecode import Payloads, decode_each, decode_frames, unsigned_raw, vectorised  # noqa: E402

SCALES = [1, 2, -3, 7.0, 0.1, 1.5, -0.25, 1e10, 3.0e300, 1 << 40]
OFFSETS = [0, 1, -5, 3.0, -0.5, 1e15, 2.5e-7, (1 << 60) + 1]


@st.composite
def messages(draw: Any) -> Message:
    """A message of 1..64 bytes with signals that fit it without overlapping (cantools' strict check)."""
    size = draw(st.sampled_from([1, 2, 3, 4, 5, 8, 12, 16, 64]))
    signals: list[Signal] = []
    for k in range(draw(st.integers(1, 6))):
        is_float = draw(st.booleans()) and draw(st.booleans())
        length = draw(st.sampled_from([16, 32, 64])) if is_float else draw(st.integers(1, 64))
        sig = Signal(f"s{k}", draw(st.integers(0, 8 * size - 1)), length,
                     byte_order=draw(st.sampled_from(["little_endian", "big_endian"])),
                     is_signed=draw(st.booleans()),
                     conversion=BaseConversion.factory(scale=draw(st.sampled_from(SCALES)),
                                                       offset=draw(st.sampled_from(OFFSETS)), is_float=is_float))
        try:  # kept if the message stays valid with it (inside the message, no overlap)
            Message(0x123, "M", size, [*signals, sig], strict=True)
        except Exception:  # noqa: BLE001 - cantools refuses the layout
            continue
        signals.append(sig)
    return Message(0x123, "M", size, signals, strict=True)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal, NaN where NaN (and -0.0 told from 0.0)."""
    return bool(np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b)))


@settings(max_examples=300, deadline=None)
@given(msg=messages(), data=st.data())
def test_numpy_decoding_equals_cantools_frame_by_frame(msg: Message, data: Any) -> None:
    size = int(msg.length)
    lengths = st.sampled_from([size, size, size, size + 1, size + 3, max(size - 1, 0), 0])
    payloads = data.draw(st.lists(lengths.flatmap(lambda n: st.binary(min_size=n, max_size=n)), min_size=1,
                                  max_size=12))
    stack = Payloads.of(payloads)
    names = [s.name for s in msg.signals]
    assert vectorised(msg)
    fast, slow = decode_frames(msg, stack, names), decode_each(msg, stack, names)
    np.testing.assert_array_equal(fast.ok, slow.ok)
    np.testing.assert_array_equal(fast.ok, [len(p) >= size for p in payloads])
    for name in names:
        assert _same(fast.values[name], slow.values[name]), (name, fast.values[name], slow.values[name])
        np.testing.assert_array_equal(fast.carried[name], slow.carried[name])


def test_float_signals_keep_nan_infinity_and_negative_zero() -> None:
    sig = Signal("f", 0, 32, byte_order="little_endian", conversion=BaseConversion.factory(is_float=True))
    msg = Message(1, "M", 4, [sig], strict=True)
    bits = [np.float32(v).tobytes() for v in (np.nan, np.inf, -np.inf, -0.0, 1.5)]
    got = decode_frames(msg, Payloads.of(bits), ["f"]).values["f"]
    assert _same(got, np.array([np.nan, np.inf, -np.inf, -0.0, 1.5]))
    assert _same(got, decode_each(msg, Payloads.of(bits), ["f"]).values["f"])


@pytest.mark.parametrize("scale,offset", [(3, (1 << 60) + 1), (1, 1), (2, -1)])
def test_large_integers_scale_exactly_as_python_integers_do(scale: int, offset: int) -> None:
    # 64-bit raw values and integer scales: exact integer arithmetic, then one rounding to float (a float
    # product would round twice: 2**53 + 1 plus 1 is 2**53 + 2, not 2**53)
    sig = Signal("n", 0, 64, byte_order="little_endian", is_signed=False,
                 conversion=BaseConversion.factory(scale=scale, offset=offset))
    msg = Message(1, "M", 8, [sig], strict=True)
    raws = [(1 << 64) - 1, (1 << 53) + 1, 12345678901234567, 5]
    got = decode_frames(msg, Payloads.of([r.to_bytes(8, "little") for r in raws]), ["n"]).values["n"]
    np.testing.assert_array_equal(got, [float(r * scale + offset) for r in raws])


def test_a_multiplexed_message_is_decoded_by_cantools() -> None:
    db = cantools.database.load_string('''VERSION ""
BS_:
BU_: N
BO_ 16 Mux: 4 N
 SG_ Sel M : 0|8@1+ (1,0) [0|255] "" N
 SG_ A m0 : 8|16@1- (0.5,0) [0|0] "" N
 SG_ B m1 : 8|16@1+ (1,0) [0|0] "" N
''', database_format="dbc")
    msg = db.get_message_by_name("Mux")
    assert not vectorised(msg)
    frames = Payloads.of([b"\x00\x10\x00\x00", b"\x01\x10\x00\x00", b"\x07\x00\x00\x00", b"\x00\x01"])
    got = decode_frames(msg, frames, ["A", "B"])
    np.testing.assert_array_equal(got.ok, [True, True, False, False])  # an unknown selector, too short
    np.testing.assert_array_equal(got.carried["A"], [True, False, False, False])
    np.testing.assert_array_equal(got.values["A"], [8.0, np.nan, np.nan, np.nan])
    np.testing.assert_array_equal(got.values["B"], [np.nan, 16.0, np.nan, np.nan])


@settings(max_examples=60, deadline=None)
@given(length=st.integers(1, 64), start=st.integers(0, 63), big=st.booleans(),
       payloads=st.lists(st.binary(min_size=7, max_size=9), min_size=1, max_size=8))
def test_a_counters_raw_value_is_cantools_unscaled_integer(length: int, start: int, big: bool,
                                                          payloads: list[bytes]) -> None:
    sig = Signal("c", start, length, byte_order="big_endian" if big else "little_endian")
    try:
        msg = Message(1, "M", 8, [sig], strict=True)
    except Exception:  # noqa: BLE001 - outside the message
        return
    ok, raw = unsigned_raw(msg, Payloads.of(payloads), "c")
    for i, p in enumerate(payloads):
        assert ok[i] == (len(p) >= 8)
        if ok[i]:
            assert int(raw[i]) == dict(msg.decode(p, decode_choices=False, scaling=False))["c"]


def test_a_bad_payload_stack_or_signal_is_refused_naming_the_field() -> None:
    with pytest.raises(ValueError, match=r"Payloads\.data: expected a \(frames, bytes\) uint8"):
        Payloads(np.zeros((2, 8), dtype=np.int16), np.zeros(2, dtype=np.int64))
    with pytest.raises(ValueError, match=r"Payloads\.length: expected \(2,\) int64"):
        Payloads(np.zeros((2, 8), dtype=np.uint8), np.zeros(3, dtype=np.int64))
    with pytest.raises(ValueError, match=r"Payloads\.length: each must be in 0\.\.8"):
        Payloads(np.zeros((2, 8), dtype=np.uint8), np.array([1, 9], dtype=np.int64))
    msg = Message(1, "M", 1, [Signal("a", 0, 8)], strict=True)
    with pytest.raises(ValueError, match="message M has no signal 'b'"):
        decode_frames(msg, Payloads.of([b"\x01"]), ["b"])
