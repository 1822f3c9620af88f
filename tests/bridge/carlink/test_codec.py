"""Car-link codec: golden bytes, the documented CRC and layout, rejections, sequence arithmetic."""

import re
import struct
import zlib

import pytest

from tests.bridge.carlink_helpers import CAR, forge
from trustfg.bridge.carlink import (
    DATAGRAM_SIZE,
    CarLinkError,
    Command,
    Flags,
    codec,
    decode_command,
    encode_command,
    seq_after,
)

GOLDEN = Command(CAR, 0x01020304, 12.5, 0.25, -0.5)
GOLDEN_HEX = ("54 46 01 03 04 03 02 01 00 00 00 00 00 00 29 40 "
              "00 00 80 3e 00 00 00 bf 00 00 bb 42 e0 c0")
GOLDEN_E_STOP = Command(7, 0xFFFFFFFF, 1234.0625, 0.0, 0.0, Flags.E_STOP)
GOLDEN_E_STOP_HEX = ("54 46 01 07 ff ff ff ff 00 00 00 00 40 48 93 40 "
                     "00 00 00 00 00 00 00 00 01 00 0b 9d 69 e9")


def test_golden_bytes():
    assert encode_command(GOLDEN) == bytes.fromhex(GOLDEN_HEX)
    assert decode_command(bytes.fromhex(GOLDEN_HEX)) == GOLDEN
    assert encode_command(GOLDEN_E_STOP) == bytes.fromhex(GOLDEN_E_STOP_HEX)
    assert decode_command(bytes.fromhex(GOLDEN_E_STOP_HEX)) == GOLDEN_E_STOP


def test_worked_example_in_docstring_is_the_golden_datagram():
    doc = codec.__doc__
    example = doc[doc.index("Worked example"):doc.index("Datagram (version 2")]
    hex_lines = re.findall(r"^ {4}((?:[0-9a-f]{2} ?)+)$", example, flags=re.MULTILINE)
    assert bytes.fromhex(" ".join(hex_lines)) == encode_command(GOLDEN)
    assert "0xC0E042BB" in example and zlib.crc32(encode_command(GOLDEN)[:26]) == 0xC0E042BB


def crc32_bitwise(data: bytes) -> int:
    """The CRC as the module docstring tells a firmware writer to compute it."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0xEDB88320 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFF


def test_documented_crc_parameters_are_zlib():
    assert crc32_bitwise(b"123456789") == zlib.crc32(b"123456789") == 0xCBF43926
    body = encode_command(GOLDEN)[:26]
    assert crc32_bitwise(body) == struct.unpack("<I", encode_command(GOLDEN)[26:])[0]


def test_layout_offsets():
    data = encode_command(Command(200, 0xA1B2C3D4, -3.0, 1.5, -2.0, Flags.STOP | Flags.E_STOP))
    assert len(data) == DATAGRAM_SIZE == 30
    assert data[0:2] == b"TF" and data[2] == 1 and data[3] == 200
    assert struct.unpack_from("<I", data, 4)[0] == 0xA1B2C3D4
    assert struct.unpack_from("<d", data, 8)[0] == -3.0
    assert struct.unpack_from("<ff", data, 16) == (1.5, -2.0)
    assert struct.unpack_from("<H", data, 24)[0] == 0x0003


@pytest.mark.parametrize("data, reason", [
    (b"", "length"),
    (forge()[:-1], "length"),
    (forge() + b"\x00", "length"),
    (forge(magic=b"FT"), "magic"),
    (forge(version=0), "version"),
    (forge(version=2), "version"),
    (forge(crc=zlib.crc32(forge()[:26]) ^ 1), "crc"),
    (forge()[:10] + b"\x01" + forge()[11:], "crc"),
    (forge(car_id=0), "car_id"),
    (forge(v=float("nan")), "non_finite"),
    (forge(v=float("inf")), "non_finite"),
    (forge(omega=float("-inf")), "non_finite"),
    (forge(omega=float("nan")), "non_finite"),
    (forge(stamp_s=float("nan")), "non_finite"),
    (forge(flags=0x0010), "flags"),
    (forge(flags=0x0005), "flags"),  # E_STOP with RELEASE
    (forge(flags=0x8001), "flags"),
], ids=lambda x: x if isinstance(x, str) else None)
def test_decode_rejects_with_reason(data, reason):
    with pytest.raises(CarLinkError) as err:
        decode_command(data)
    assert err.value.reason == reason
    assert isinstance(err.value, ValueError)
    assert reason in str(err.value)


def test_decode_rejects_non_bytes_with_carlink_error():
    with pytest.raises(CarLinkError, match="type"):
        decode_command("TF" * 15)  # type: ignore[arg-type]


def test_decode_accepts_bytearray_and_memoryview():
    data = encode_command(GOLDEN)
    assert decode_command(bytearray(data)) == decode_command(memoryview(data)) == GOLDEN


@pytest.mark.parametrize("fields, reason", [
    (dict(car_id=0), "car_id"),
    (dict(car_id=256), "car_id"),
    (dict(seq=-1), "range"),
    (dict(seq=2**32), "range"),
    (dict(v_mps=float("nan")), "non_finite"),
    (dict(omega_radps=1e39), "range"),
    (dict(stamp_s=float("inf")), "non_finite"),
    (dict(flags=16), "flags"),
    (dict(flags=5), "flags"),
    (dict(car_id=1.5), "type"),
    (dict(v_mps="fast"), "type"),
])
def test_command_validates_fields(fields, reason):
    base = dict(car_id=1, seq=0, stamp_s=0.0, v_mps=0.0, omega_radps=0.0, flags=0)
    with pytest.raises(CarLinkError) as err:
        Command(**{**base, **fields})
    assert err.value.reason == reason


def test_command_flags_become_flags():
    cmd = Command(1, 0, 0.0, 0.0, 0.0, 3)
    assert isinstance(cmd.flags, Flags) and cmd.flags == Flags.E_STOP | Flags.STOP
    assert cmd.e_stop and cmd.stop


def test_encode_rounds_to_f32():
    cmd = decode_command(encode_command(Command(1, 0, 0.1, 0.1, 0.1)))
    assert cmd.stamp_s == 0.1  # f64 kept exactly
    assert cmd.v_mps == struct.unpack("<f", struct.pack("<f", 0.1))[0] != 0.1


# --------------------------------------------------------------- sequence arithmetic


@pytest.mark.parametrize("seq, last, after", [
    (1, 0, True), (0, 1, False), (5, 5, False),
    (0, 0xFFFFFFFF, True), (0xFFFFFFFF, 0, False), (10, 0xFFFFFFF0, True),
    (2**31 - 1, 0, True), (2**31, 0, False), (0, 2**31, False),
])
def test_seq_after(seq, last, after):
    assert seq_after(seq, last) is after
