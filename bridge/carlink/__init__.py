"""Car link: velocity commands from a car process to its car, one UDP datagram each.

Pure pieces: :mod:`.frame` (constants, layouts, CRC and MAC; quick to import),
:mod:`.codec` (the validated :class:`Command`, and the byte table a firmware writer
starts from), :mod:`.answer` (a car's answer to a PING), :mod:`.receiver`
(:class:`CommandFilter`, the rules a car runs; mocap-sim's cars run this very class) and
:mod:`.keys`. I/O: :mod:`.link` (:class:`CommandSender`, :class:`CommandReceiver`) and
:mod:`.direct` (one E_STOP with the standard library alone). :mod:`.conformance` is
``trustfg carlink-test`` and is not re-exported.

Everything else public is re-exported here and loads on first use (PEP 562), so importing
:mod:`.frame`, :mod:`.keys` or :mod:`.direct` alone stays quick: ``trustfg stop`` sends its
first E_STOPs with them. Imports point one way, from ``frame`` up (docs/design/links.md,
"The car link's sockets"); the wire format for firmware writers is docs/carlink.md.
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

