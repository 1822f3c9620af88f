"""NatNet test helpers: the real Motive captures, a minimal pcapng reader, and the small
assertion helpers the codec's test modules share.

The captures are test data in ``tests/data/natnet-captures`` (with their licences and
SHA256SUMS); a missing file is an error, never a skip.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Callable, NamedTuple

import pytest

from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V3_0, NatNetError, Version

CAPTURES = Path(__file__).resolve().parent.parent / "data" / "natnet-captures"
V3_DIR = "natnet3_motive2.1_python_natnet"
V2_DIR = "natnet2x_motive1.x_natnet-decode"
V3_FRAME = "mocapframe_packet_v3.bin"


def approx(values, rel=0, abs=5e-7):
    return pytest.approx(tuple(values), rel=rel, abs=abs)


def reason_of(packet: bytes, version: Version = V3_0, **kw) -> str:
    """The ``reason`` of the NatNetError that decoding ``packet`` must raise."""
    with pytest.raises(NatNetError) as info:
        nn.deserialize(packet, version, **kw)
    assert str(info.value)
    return info.value.reason


class UdpDatagram(NamedTuple):
    src: str
    src_port: int
    dst: str
    dst_port: int
    payload: bytes


def read_pcapng(path: Path) -> list[UdpDatagram]:
    """UDP/IPv4 datagrams of a pcapng file with Ethernet link layers.

    pcapng: blocks of ``uint32 type, uint32 total length, body, uint32 total length``.
    The section header block (0x0A0D0D0A) holds the byte-order magic 0x1A2B3C4D; interface
    description blocks (1) give each interface's link type; enhanced packet blocks (6) hold
    ``uint32 interface, uint32 ts high, uint32 ts low, uint32 captured, uint32 original``
    and the frame, padded to 4 bytes. Other blocks are skipped.
    """
    data = path.read_bytes()
    order, off, link_types, out = "<", 0, [], []
    while off + 12 <= len(data):
        (block_type,) = struct.unpack_from("<I", data, off)
        if block_type == 0x0A0D0D0A:
            magic = data[off + 8:off + 12]
            order = "<" if magic == b"\x4d\x3c\x2b\x1a" else ">"
            link_types = []
        (length,) = struct.unpack_from(order + "I", data, off + 4)
        if length < 12 or off + length > len(data):
            raise ValueError(f"bad pcapng block at {off}")
        body = data[off + 8:off + length - 4]
        if block_type == 1:
            link_types.append(struct.unpack_from(order + "H", body, 0)[0])
        elif block_type == 6:
            interface, _, _, captured, _ = struct.unpack_from(order + "5I", body, 0)
            if link_types[interface] == 1:  # Ethernet
                datagram = _udp_in_ethernet(body[20:20 + captured])
                if datagram is not None:
                    out.append(datagram)
        off += length
    return out


def _udp_in_ethernet(frame: bytes) -> UdpDatagram | None:
    (ethertype,) = struct.unpack_from(">H", frame, 12)
    off = 14
    if ethertype == 0x8100:  # 802.1Q tag
        (ethertype,) = struct.unpack_from(">H", frame, 16)
        off = 18
    if ethertype != 0x0800:
        return None
    ip = frame[off:]
    ihl = (ip[0] & 0x0F) * 4
    total_length, flags_fragment = struct.unpack_from(">H2xH", ip, 2)
    if ip[9] != 17 or flags_fragment & 0x3FFF:  # not UDP, or a fragment
        return None
    src, dst = (".".join(map(str, ip[i:i + 4])) for i in (12, 16))
    udp = ip[ihl:total_length]
    src_port, dst_port, udp_length = struct.unpack_from(">HHH", udp, 0)
    return UdpDatagram(src, src_port, dst, dst_port, bytes(udp[8:udp_length]))


def _require(path: Path) -> Path:
    if not path.exists():
        raise FileNotFoundError(f"NatNet capture missing from the test data: {path}")
    return path


@pytest.fixture(scope="session")
def captures() -> Path:
    return _require(CAPTURES)


@pytest.fixture(scope="session")
def capture(captures: Path) -> Callable[[str], bytes]:
    """``capture("natnet3.../file.bin")`` or ``capture("file.bin")`` (looked up in the v3
    folder, then ``derived/``) -> bytes."""

    def read(name: str) -> bytes:
        for candidate in (captures / name, captures / V3_DIR / name, captures / "derived" / name):
            if candidate.is_file():
                return candidate.read_bytes()
        raise FileNotFoundError(name)

    return read


@pytest.fixture(scope="session")
def traffic(captures: Path) -> list[UdpDatagram]:
    return read_pcapng(captures / V3_DIR / "traffic.pcapng")


@pytest.fixture(scope="session")
def sample_client_log(captures: Path) -> str:
    return (captures / V3_DIR / "SampleClient_output.txt").read_text(errors="replace")
