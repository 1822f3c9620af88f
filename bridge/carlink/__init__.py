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
  the operator's tools (:meth:`CommandSender.for_car` builds it from a car's config) and
  :class:`CommandReceiver`, a reader thread feeding a :class:`CommandFilter`.
* :mod:`.keys` -- where a car's link key comes from (its key file) and how one is made.

Imports point one way: ``answer``, ``receiver``, ``keys`` and ``link`` use ``codec``,
``receiver`` uses ``answer``, ``link`` uses ``answer``, ``receiver`` and ``keys``.
Everything public is re-exported here, so callers import from ``trustfg.bridge.carlink``.
"""

from .answer import ANSWER_SIZE, ANSWER_V2_SIZE, Answer, CarState, decode_answer, encode_answer
from .codec import (
    DATAGRAM_SIZE,
    DATAGRAM_V2_SIZE,
    KEY_BYTES,
    MAC_BYTES,
    MAGIC,
    SEQ_MODULUS,
    SOURCE_CAR_PROCESS,
    SOURCE_OPERATOR,
    VERSION,
    VERSION_2,
    CarLinkError,
    Command,
    Flags,
    decode_command,
    decode_command_v2,
    encode_command,
    encode_command_v2,
    seq_after,
)
from .keys import link_key, new_key, write_key_file
from .link import (
    Clock,
    CommandReceiver,
    CommandSender,
    SenderStats,
    new_session,
)
from .receiver import (
    DEFAULT_RESYNC_AFTER_S,
    DEFAULT_WATCHDOG_TIMEOUT_S,
    CommandFilter,
    FilterCounters,
)

__all__ = [
    "DATAGRAM_SIZE", "DATAGRAM_V2_SIZE", "KEY_BYTES", "MAC_BYTES", "MAGIC", "SEQ_MODULUS",
    "SOURCE_CAR_PROCESS", "SOURCE_OPERATOR", "VERSION", "VERSION_2", "CarLinkError", "Command",
    "Flags", "decode_command", "decode_command_v2", "encode_command", "encode_command_v2", "seq_after",
    "link_key", "new_key", "write_key_file", "new_session",
    "DEFAULT_RESYNC_AFTER_S", "DEFAULT_WATCHDOG_TIMEOUT_S", "CommandFilter", "FilterCounters",
    "ANSWER_SIZE", "ANSWER_V2_SIZE", "Answer", "CarState", "decode_answer", "encode_answer",
    "Clock", "CommandReceiver", "CommandSender", "SenderStats",
]
