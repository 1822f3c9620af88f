"""Car link: velocity commands from a car process to its car, one UDP datagram each.

Three pieces, each documented where it lives:

* :mod:`.codec` -- the bytes (pure): the datagram layout, the flags, the CRC in C and a
  worked example; :func:`encode_command` / :func:`decode_command`. Start here to write
  firmware. :mod:`.frame` holds its constants, layouts and framing, quick to import.
* :mod:`.receiver` -- the car's rules (pure): :class:`CommandFilter`, which datagrams a car
  accepts and what it applies (sequence numbers, restarts, watchdog, E_STOP/STOP). Real
  firmware runs these rules; mocap_sim's simulated car runs this very class.
* :mod:`.answer` -- the bytes a car sends back to a PING datagram (pure).
* :mod:`.link` -- the sockets (thin I/O): :class:`CommandSender` for the car process and
  the operator's tools (:meth:`CommandSender.for_car` builds it from a car's config) and
  :class:`CommandReceiver`, a reader thread feeding a :class:`CommandFilter`.
* :mod:`.direct` -- one E_STOP datagram with the standard library alone (``trustfg stop``'s
  first, before the rest loads).
* :mod:`.keys` -- where a car's link key comes from (its key file) and how one is made.
* :mod:`.conformance` -- ``trustfg carlink-test``: a car probed over UDP, rule by rule of
  :mod:`.receiver` (its probes and socket in :mod:`.conformance_probes`). Not re-exported.

Imports point one way: ``codec``, ``answer``, ``receiver``, ``keys``, ``direct`` and
``link`` use ``frame``; ``answer``, ``receiver`` and ``link`` use ``codec``; ``receiver``
uses ``answer``; ``link`` uses ``answer``, ``receiver``, ``keys`` and ``direct``;
``conformance_probes`` uses ``frame``, ``answer``, ``direct``, ``keys`` and ``receiver``'s
defaults, and ``conformance`` uses it.
Everything public is re-exported here, so callers import from ``trustfg.bridge.carlink``;
the re-exports load on first use (PEP 562), so that importing :mod:`.frame`, :mod:`.keys`
or :mod:`.direct` alone stays quick: ``trustfg stop`` sends its first E_STOPs with them.
"""

from __future__ import annotations

import importlib

_HOMES = {
    "frame": ("DATAGRAM_SIZE", "DATAGRAM_V2_SIZE", "KEY_BYTES", "MAC_BYTES", "MAGIC", "SEQ_MODULUS",
              "SOURCE_CAR_PROCESS", "SOURCE_OPERATOR", "VERSION", "VERSION_2", "CarLinkError", "Flags",
              "new_session"),
    "codec": ("Command", "decode_command", "decode_command_v2", "encode_command", "encode_command_v2", "seq_after"),
    "keys": ("link_key", "new_key", "write_key_file"),
    "receiver": ("DEFAULT_RESYNC_AFTER_S", "DEFAULT_WATCHDOG_TIMEOUT_S", "CommandFilter", "FilterCounters"),
    "answer": ("ANSWER_SIZE", "ANSWER_V2_SIZE", "Answer", "CarState", "decode_answer", "encode_answer"),
    "direct": ("E_STOP_FLAGS", "send_e_stop"),
    "link": ("Clock", "CommandReceiver", "CommandSender", "SenderStats"),
}
_HOME_OF = {name: module for module, names in _HOMES.items() for name in names}
__all__ = list(_HOME_OF)


def __getattr__(name: str):
    module = _HOME_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # once: later lookups find it here
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))

