"""Car link: velocity commands from a car process to its car, one UDP datagram each.

Three pieces, each documented where it lives:

* :mod:`.codec` -- the bytes (pure): the datagram layout, the flags, the CRC in C and a
  worked example; :func:`encode_command` / :func:`decode_command`. Start here to write
  firmware.
* :mod:`.receiver` -- the car's rules (pure): :class:`CommandFilter`, which datagrams a car
  accepts and what it applies (sequence numbers, restarts, watchdog, E_STOP/STOP). Real
  firmware runs these rules; mocap_sim's simulated car runs this very class.
* :mod:`.link` -- the sockets (thin I/O): :class:`CommandSender` for the car process and
  :class:`CommandReceiver`, a reader thread feeding a :class:`CommandFilter`.

Imports point one way: ``receiver`` and ``link`` use ``codec``, ``link`` uses ``receiver``.
Everything public is re-exported here, so callers import from ``trustfg.bridge.carlink``.
"""

from .codec import (
    DATAGRAM_SIZE,
    MAGIC,
    SEQ_MODULUS,
    VERSION,
    CarLinkError,
    Command,
    Flags,
    decode_command,
    encode_command,
    seq_after,
)
from .link import (
    Clock,
    CommandReceiver,
    CommandSender,
    SenderStats,
)
from .receiver import (
    DEFAULT_RESYNC_AFTER_S,
    DEFAULT_WATCHDOG_TIMEOUT_S,
    CommandFilter,
    FilterCounters,
)

__all__ = [
    "DATAGRAM_SIZE", "MAGIC", "SEQ_MODULUS", "VERSION", "CarLinkError", "Command", "Flags",
    "decode_command", "encode_command", "seq_after",
    "DEFAULT_RESYNC_AFTER_S", "DEFAULT_WATCHDOG_TIMEOUT_S", "CommandFilter", "FilterCounters",
    "Clock", "CommandReceiver", "CommandSender", "SenderStats",
]
