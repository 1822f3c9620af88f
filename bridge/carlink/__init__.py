"""Car link: velocity commands from a car process to its car, one UDP datagram each.

Three pieces, each documented where it lives:

* :mod:`.codec` -- the bytes (pure): the datagram layout, the flags, the CRC in C and a
  worked example; :func:`encode_command` / :func:`decode_command`. Start here to write
  firmware.
* :mod:`.receiver` -- the car's rules (pure): :class:`CommandFilter`, which datagrams a car
  accepts and what it applies (sequence numbers, restarts, watchdog, E_STOP/STOP). Real
  firmware runs these rules; mocap_sim's simulated car runs this very class.
* :mod:`.answer` -- the bytes a car sends back to a PING datagram (pure).
* :mod:`.link` -- the sockets (thin I/O): :class:`CommandSender` for the car process and
  the operator's tools (:func:`open_sender` builds it from a car's config) and
  :class:`CommandReceiver`, a reader thread feeding a :class:`CommandFilter`.

Imports point one way: ``answer``, ``receiver`` and ``link`` use ``codec``, ``receiver``
uses ``answer``, ``link`` uses both.
Everything public is re-exported here, so callers import from ``trustfg.bridge.carlink``.
"""

from .answer import ANSWER_SIZE, Answer, CarState, decode_answer, encode_answer
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
    open_sender,
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
    "ANSWER_SIZE", "Answer", "CarState", "decode_answer", "encode_answer",
    "Clock", "CommandReceiver", "CommandSender", "SenderStats", "open_sender",
]
