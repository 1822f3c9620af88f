"""Car-link test helpers: the car id the tests use and datagrams built from raw fields."""

import struct
import zlib

from trustfg.bridge.carlink import Command, Flags, encode_command

CAR = 3


def forge(magic=b"TF", version=1, car_id=CAR, seq=1, stamp_s=1.0, v=0.5, omega=0.25, flags=0,
          crc=None):
    """Raw datagram with any field values (the codec would refuse to build some of them)."""
    body = struct.pack("<2sBBIdffH", magic, version, car_id, seq, stamp_s, v, omega, flags)
    return body + struct.pack("<I", zlib.crc32(body) if crc is None else crc)


def datagram(seq, car_id=CAR, v=0.5, omega=0.25, flags=Flags.NONE, stamp_s=0.0):
    return encode_command(Command(car_id, seq, stamp_s, v, omega, flags))
