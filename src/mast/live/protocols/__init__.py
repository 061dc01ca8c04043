"""The scanner protocols MAST speaks, each one module: its codec, its client and the
scanner's side for the emulator (:mod:`mast.live.protocols.base`).

* ``sick``: SICK LMS1xx / LMS5xx / TiM5xx, CoLa-A on TCP port 2111 (:mod:`.sick`).
* ``hokuyo``: Hokuyo UST / UTM, SCIP 2.0 on TCP port 10940 (:mod:`.hokuyo`).
"""

from __future__ import annotations

from collections.abc import Mapping

from mast.errors import InputError
from mast.live.protocols import hokuyo, sick
from mast.live.protocols.base import Emulation, Protocol

__all__ = ["PROTOCOLS", "Emulation", "Protocol", "protocol"]

#: Every protocol by name: its URL scheme and ``mast emulate`` kind.
PROTOCOLS: Mapping[str, Protocol] = {p.name: p for p in (sick.PROTOCOL, hokuyo.PROTOCOL)}


def protocol(name: str) -> Protocol:
    """The protocol called ``name``; an :class:`InputError` listing the known ones if none."""
    try:
        return PROTOCOLS[name]
    except KeyError:
        raise InputError(f"unknown scanner kind {name!r}; known: {', '.join(PROTOCOLS)}") from None
