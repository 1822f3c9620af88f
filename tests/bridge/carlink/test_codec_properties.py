"""Car link properties: round trips, hostile bytes, sequence arithmetic, filter invariants."""

import math
import struct
import zlib

from hypothesis import given, settings
from hypothesis import strategies as st

from trustfg.bridge.carlink import (
    DATAGRAM_SIZE,
    SEQ_MODULUS,
    CarLinkError,
    Command,
    CommandFilter,
    Flags,
    decode_command,
    encode_command,
    seq_after,
)

PROPERTY = settings(max_examples=300, deadline=None)
seqs = st.integers(0, SEQ_MODULUS - 1)
f32s = st.floats(width=32, allow_nan=False, allow_infinity=False)
commands = st.builds(
    Command,
    car_id=st.integers(1, 255),
    seq=seqs,
    stamp_s=st.floats(allow_nan=False, allow_infinity=False),
    v_mps=f32s,
    omega_radps=f32s,
    flags=st.sampled_from([Flags.NONE, Flags.E_STOP, Flags.STOP, Flags.E_STOP | Flags.STOP, Flags.RELEASE,
                           Flags.PING, Flags.STOP | Flags.PING, Flags.E_STOP | Flags.STOP | Flags.PING]),
)


def decodes_or_carlink_error(data):
    """decode_command's contract: a Command or CarLinkError, nothing else."""
    try:
        cmd = decode_command(data)
    except CarLinkError:
        return None
    assert isinstance(cmd, Command)
    return cmd


@PROPERTY
@given(commands)
def test_round_trip(cmd):
    data = encode_command(cmd)
    assert len(data) == DATAGRAM_SIZE
    again = decode_command(data)
    assert again == cmd
    assert encode_command(again) == data  # also keeps -0.0 and subnormals bit for bit


@PROPERTY
@given(st.binary(max_size=64))
def test_random_bytes_never_raise_anything_else(data):
    decodes_or_carlink_error(data)
    assert CommandFilter(3).accept(data, 0.0) in (None, decodes_or_carlink_error(data))


@PROPERTY
@given(version=st.integers(0, 3), car_id=st.integers(0, 255), seq=seqs,
       stamp_bits=st.integers(0, 2**64 - 1), v_bits=st.integers(0, 2**32 - 1),
       omega_bits=st.integers(0, 2**32 - 1),
       flags=st.one_of(st.integers(0, 15), st.integers(0, 0xFFFF)))
def test_field_checks_against_the_spec(version, car_id, seq, stamp_bits, v_bits, omega_bits, flags):
    """Any field bit patterns behind a valid CRC: accepted exactly when the spec says so."""
    raw = struct.pack("<2sBBIQIIH", b"TF", version, car_id, seq, stamp_bits, v_bits, omega_bits, flags)
    data = raw + struct.pack("<I", zlib.crc32(raw))
    stamp, = struct.unpack("<d", struct.pack("<Q", stamp_bits))
    v, omega = struct.unpack("<ff", struct.pack("<II", v_bits, omega_bits))
    valid = (version == 1 and car_id != 0 and flags & ~0xF == 0 and flags & 0x5 != 0x5
             and all(math.isfinite(x) for x in (stamp, v, omega)))
    cmd = decodes_or_carlink_error(data)
    assert (cmd is not None) == valid
    if cmd is not None:
        assert encode_command(cmd) == data  # anything accepted is canonical


@PROPERTY
@given(commands, st.sets(st.integers(0, 8 * DATAGRAM_SIZE - 1), min_size=1, max_size=3))
def test_bit_errors_are_always_caught(cmd, bits):
    data = bytearray(encode_command(cmd))
    for bit in bits:
        data[bit // 8] ^= 1 << (bit % 8)
    try:
        decode_command(bytes(data))
    except CarLinkError:
        return
    raise AssertionError(f"{len(bits)}-bit error not detected")


@PROPERTY
@given(commands, st.integers(0, DATAGRAM_SIZE - 1), st.integers(0, 255), st.binary(max_size=4),
       st.integers(0, DATAGRAM_SIZE))
def test_mutated_datagrams(cmd, index, value, extra, cut):
    data = encode_command(cmd)
    replaced = data[:index] + bytes([value]) + data[index + 1:]
    assert decodes_or_carlink_error(replaced) in (None, cmd)
    assert decodes_or_carlink_error(data[:cut] + extra) in (None, cmd)
    f = CommandFilter(cmd.car_id)
    for mutant in (replaced, data[:cut] + extra, data + extra, data[::-1]):
        f.accept(mutant, 0.0)


@PROPERTY
@given(seqs, seqs)
def test_seq_after_is_a_strict_order_locally(a, b):
    distance = (a - b) % SEQ_MODULUS
    if distance in (0, SEQ_MODULUS // 2):
        assert not seq_after(a, b) and not seq_after(b, a)
    else:
        assert seq_after(a, b) != seq_after(b, a)
    assert seq_after((a + 1) % SEQ_MODULUS, a)


@PROPERTY
@given(seqs, st.lists(st.integers(-5, 5), max_size=60))
def test_filter_accepts_only_forward_within_a_session(start, steps):
    """Without a silence long enough to resync, accepted seqs only move forward."""
    f = CommandFilter(7)
    seq, accepted, now = start, [], 0.0
    for step in steps:
        seq = (seq + step) % SEQ_MODULUS
        now += 0.01
        cmd = f.accept(encode_command(Command(7, seq, now, 0.1, 0.0)), now)
        if cmd is not None:
            accepted.append(cmd.seq)
    assert all(seq_after(b, a) for a, b in zip(accepted, accepted[1:]))
    counters = f.counters
    assert counters.accepted == len(accepted) and counters.resynced == 0
    assert counters.accepted + counters.rejected == len(steps)


@PROPERTY
@given(st.lists(st.tuples(st.binary(max_size=40), st.floats(0.0, 5.0)), max_size=40), commands)
def test_filter_never_raises_and_stops_when_told(noise, cmd):
    f = CommandFilter(cmd.car_id)
    assert f.accept(encode_command(cmd), 0.0) == cmd
    if cmd.e_stop or cmd.stop or cmd.ping:  # a PING is never applied
        assert f.active_command(0.0) == (0.0, 0.0)
    else:
        assert f.active_command(0.0) == (cmd.v_mps, cmd.omega_radps)
    for data, now in noise:
        f.accept(data, now)
        v, omega = f.active_command(now)
        assert isinstance(v, float) and isinstance(omega, float)
    if cmd.e_stop:  # noise cannot release it (that takes a valid RELEASE in sequence)
        assert f.e_stop_latched and f.active_command(0.0) == (0.0, 0.0)
