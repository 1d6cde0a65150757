"""OpenTrackIO's UDP transport: each datagram is a 16-byte header followed by the payload (a JSON or
CBOR sample, or one segment of it).

Header (big-endian; OpenTrackIO documentation, "Transport recommendations: Packet Header"):

=======  ======  ===================================================================================
offset   bytes   field
=======  ======  ===================================================================================
0        4       identifier ``b"OTrk"``
4        1       reserved (0)
5        1       encoding: 0x01 JSON, 0x02 CBOR
6        2       sequence number (1 .. 65535; this module wraps 65535 -> 1)
8        4       segment offset: byte offset of this segment in the whole payload (0 when unsegmented)
12       2       bit 15: last-segment flag (1 for the only or the last segment); bits 0-14: length of
                 this packet's payload in bytes
14       2       Fletcher-16 checksum (sums modulo 255, ``sum2 << 8 | sum1``) of bytes 0-13 and the payload
=======  ======  ===================================================================================

Payloads longer than :data:`MAX_SEGMENT` bytes (a 1500-byte MTU less the header) are split into
segments that share the sequence number. The standard's multicast address for source number N is
``235.135.1.N``, port 55555; glradial sends wherever it is told (``--send HOST:PORT``).
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from contextlib import closing
from dataclasses import dataclass
from typing import Iterable

__all__ = ["IDENTIFIER", "ENCODING_JSON", "ENCODING_CBOR", "MAX_SEGMENT", "fletcher16", "packets", "Packet", "parse_packet",
           "send_payloads", "parse_address", "SampleSender", "SampleReceiver", "reassemble"]

IDENTIFIER = b"OTrk"
ENCODING_JSON = 0x01
ENCODING_CBOR = 0x02
HEADER = struct.Struct("!4sBBHIH")  # everything but the checksum: 14 bytes
HEADER_SIZE = HEADER.size + 2
MAX_SEGMENT = 1500 - HEADER_SIZE
LAST_SEGMENT = 0x8000


def fletcher16(data: bytes) -> int:
    """Fletcher-16 of ``data``: ``sum1 = Σ byte mod 255``, ``sum2 = Σ sum1 mod 255``, ``sum2 << 8 | sum1``."""
    sum1 = sum2 = 0
    for byte in data:
        sum1 = (sum1 + byte) % 255
        sum2 = (sum2 + sum1) % 255
    return (sum2 << 8) | sum1


def packets(payload: bytes, sequence: int, encoding: int = ENCODING_JSON) -> list[bytes]:
    """The datagrams carrying ``payload`` with ``sequence`` (1 .. 65535)."""
    if not 1 <= sequence <= 0xFFFF:
        raise ValueError(f"sequence must be in 1 .. 65535, got {sequence}")
    if encoding not in (ENCODING_JSON, ENCODING_CBOR):
        raise ValueError(f"encoding must be 0x01 (JSON) or 0x02 (CBOR), got {encoding!r}")
    if not payload:
        raise ValueError("payload must not be empty")
    out = []
    for offset in range(0, len(payload), MAX_SEGMENT):
        segment = payload[offset : offset + MAX_SEGMENT]
        last = LAST_SEGMENT if offset + MAX_SEGMENT >= len(payload) else 0
        header = HEADER.pack(IDENTIFIER, 0, encoding, sequence, offset, last | len(segment))
        out.append(header + struct.pack("!H", fletcher16(header + segment)) + segment)
    return out


@dataclass(frozen=True)
class Packet:
    """A parsed datagram."""

    encoding: int
    sequence: int
    offset: int
    last: bool
    payload: bytes


def parse_packet(data: bytes) -> Packet:
    """Parse and check one datagram: ``ValueError`` for a short packet, a wrong identifier, a length
    that disagrees with the datagram or a bad checksum."""
    if len(data) < HEADER_SIZE:
        raise ValueError(f"an OpenTrackIO packet has a {HEADER_SIZE}-byte header; got {len(data)} bytes")
    identifier, _reserved, encoding, sequence, offset, length = HEADER.unpack_from(data)
    if identifier != IDENTIFIER:
        raise ValueError(f"not an OpenTrackIO packet: identifier {identifier!r}, expected {IDENTIFIER!r}")
    payload = data[HEADER_SIZE:]
    if len(payload) != length & 0x7FFF:
        raise ValueError(f"payload length field says {length & 0x7FFF} bytes, the packet carries {len(payload)}")
    (checksum,) = struct.unpack_from("!H", data, HEADER.size)
    expected = fletcher16(data[: HEADER.size] + payload)
    if checksum != expected:
        raise ValueError(f"bad Fletcher-16 checksum: packet says {checksum:#06x}, content gives {expected:#06x}")
    return Packet(encoding, sequence, offset, bool(length & LAST_SEGMENT), payload)


def reassemble(datagrams: Iterable[bytes]) -> list[bytes]:
    """The payloads of received datagrams, in the order their last segments arrived: each payload's
    segments (same sequence number) joined by offset; a payload with a segment missing is left out."""
    parts: dict[int, dict[int, bytes]] = {}
    out = []
    for data in datagrams:
        packet = parse_packet(data)
        segments = parts.setdefault(packet.sequence, {})
        segments[packet.offset] = packet.payload
        if packet.last:
            joined, at = b"", 0
            for offset in sorted(segments):
                if offset != at:
                    break
                joined, at = joined + segments[offset], at + len(segments[offset])
            else:
                out.append(joined)
            del parts[packet.sequence]
    return out


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` -> ``(host, port)``; ``ValueError`` naming the text otherwise."""
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"address must be HOST:PORT with a port in 1 .. 65535, got {text!r}")
    return host, int(port)


class SampleSender:
    """Sends payloads one at a time, as they are made (a live stream's samples), to ``address``
    ``(host, port)`` with sequence numbers 1, 2, ... (wrapping at 65535); :attr:`sent` counts the
    payloads sent, :attr:`datagrams` the datagrams. A send the network refuses (no route, a full
    buffer) raises ``OSError`` naming the address."""

    def __init__(self, address: tuple[str, int], encoding: int = ENCODING_JSON) -> None:
        self.address, self.encoding = address, encoding
        self.sent = self.datagrams = 0
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(self, payload: bytes) -> None:
        try:
            for datagram in packets(payload, self.sent % 0xFFFF + 1, self.encoding):
                self._socket.sendto(datagram, self.address)
                self.datagrams += 1
        except OSError as err:
            raise OSError(f"cannot send OpenTrackIO packets to {self.address[0]}:{self.address[1]}: {err.strerror or err}") from None
        self.sent += 1

    def close(self) -> None:
        """Close the socket (``contextlib.closing`` makes a sender a context manager)."""
        self._socket.close()


class SampleReceiver:
    """The receiving end of :class:`SampleSender` (``glradial live --send HOST:PORT``): binds ``address``
    ``(host, port)`` at once (port 0: a free port, read back from :attr:`address`) and keeps every
    datagram that arrives, on a daemon thread, until :meth:`close` (``with`` closes it too).
    ``buffer_bytes``: the socket's receive buffer (``SO_RCVBUF``; the kernel may cap it), room for a
    burst while the thread is not scheduled.

    Example:
        >>> with SampleReceiver() as receiver:
        ...     sent = send_payloads([b'{"a": 1}', b"x" * 2000], receiver.address)
        ...     receiver.wait_for(sent)  # one datagram, then a payload in two segments
        3
        >>> receiver.payloads() == [b'{"a": 1}', b"x" * 2000]
        True
    """

    def __init__(self, address: tuple[str, int] = ("127.0.0.1", 0), buffer_bytes: int = 8 << 20) -> None:
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, buffer_bytes)
            self._socket.bind(address)
        except OSError as err:
            self._socket.close()
            raise OSError(f"cannot receive OpenTrackIO packets on {address[0]}:{address[1]}: {err.strerror or err}") from None
        self._socket.settimeout(0.1)  # how often the thread looks whether it should stop
        self.address: tuple[str, int] = self._socket.getsockname()
        self.datagrams: list[bytes] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, name="opentrackio-receiver", daemon=True)
        self._thread.start()

    def _receive(self) -> None:
        while not self._stop.is_set():
            try:
                self.datagrams.append(self._socket.recv(65536))
            except socket.timeout:
                continue

    def wait_for(self, count: int, timeout: float = 5.0) -> int:
        """Wait until ``count`` datagrams have arrived or ``timeout`` seconds have passed; how many arrived."""
        deadline = time.monotonic() + timeout
        while len(self.datagrams) < count and time.monotonic() < deadline:
            time.sleep(0.01)
        return len(self.datagrams)

    def payloads(self) -> list[bytes]:
        """The whole payloads received so far (:func:`reassemble`)."""
        return reassemble(list(self.datagrams))

    def close(self) -> None:
        """Stop receiving (what arrived stays in :attr:`datagrams`) and close the socket."""
        self._stop.set()
        self._thread.join()
        self._socket.close()

    def __enter__(self) -> "SampleReceiver":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def send_payloads(payloads: Iterable[bytes], address: tuple[str, int], *, encoding: int = ENCODING_JSON,
                  rate: float | None = None) -> int:
    """Send each payload as packets to ``address`` with sequence numbers 1, 2, ... (wrapping at
    65535), paced at ``rate`` payloads per second (None: as fast as possible); returns the number of
    datagrams sent."""
    start = time.monotonic()
    with closing(SampleSender(address, encoding)) as sender:
        for index, payload in enumerate(payloads):
            if rate:
                delay = start + index / rate - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            sender.send(payload)
    return sender.datagrams
