"""
Stream framer for the 3DM-GX3-25 single-byte protocol (ROS-free).

The protocol has no sync pattern and no length field, and header values also occur inside
float data, so a header match alone is not a frame boundary: :class:`StreamParser` slides one
byte at a time (the method of MicroStrain's own sample code; docs/driver.md, section Framing)
over a buffer fed with arbitrary chunks, and accepts a packet only when the header is known,
the full length is available and the checksum matches.  Its output does not depend on how the
bytes were chunked.
"""

from dataclasses import dataclass
import re

from .gx3_protocol import REPLY_LENGTHS


@dataclass
class ParserStats:
    """
    Counters of a :class:`StreamParser` (all cumulative).

    ``bad_checksums``: complete candidates with a wrong checksum where a packet was expected
    (right after a good packet or the previous counted bad one: a damaged packet, not a
    header-like byte inside other data); ``rejected_bytes``: every byte not in an accepted
    packet; ``resyncs``: good packets found elsewhere than the expected position.
    """

    bytes_in: int = 0
    packets: int = 0
    bad_checksums: int = 0
    rejected_bytes: int = 0
    resyncs: int = 0


class StreamParser:
    """
    Find checksummed packets in a byte stream fed in arbitrary chunks.

    ``codes``: reply codes to accept (default: every reply of the protocol).  Use
    :meth:`feed` for each chunk; it returns the complete good packets (``bytes``, header to
    checksum) in stream order.  :meth:`flush` at end of stream returns the packets still held
    back and counts a trailing partial packet as rejected.
    """

    def __init__(self, codes=None):
        """Accept the reply codes ``codes`` (iterable of ints) or all known replies."""
        codes = sorted(REPLY_LENGTHS if codes is None else codes)
        unknown = [c for c in codes if c not in REPLY_LENGTHS]
        if unknown:
            raise ValueError(f'unknown reply codes: {unknown}')
        self._lengths = [0] * 256
        for code in codes:
            self._lengths[code] = REPLY_LENGTHS[code]
        self._header_re = re.compile(b'[' + b''.join(re.escape(bytes([c])) for c in codes)
                                     + b']')
        self._buf = bytearray()
        self._base = 0          # absolute stream offset of _buf[0]
        self._expect = 0        # absolute offset where the next packet is expected
        self.stats = ParserStats()

    def reset(self):
        """Forget buffered bytes (e.g. after reopening the port); counters are kept."""
        self._base += len(self._buf)
        self._buf.clear()
        self._expect = self._base

    @property
    def buffered(self):
        """Bytes held back waiting for the rest of a candidate packet."""
        return len(self._buf)

    def feed(self, data):
        """Add a chunk of bytes; return the list of complete good packets found."""
        stats = self.stats
        stats.bytes_in += len(data)
        buf = self._buf
        buf += data
        lengths = self._lengths
        base = self._base
        expect = self._expect - base    # where the next packet is due, relative to buf
        n = len(buf)
        i = 0
        rejected = resyncs = 0
        out = []
        while i < n:
            length = lengths[buf[i]]
            if not length:
                # Not a header byte: jump to the next one (or the end).
                m = self._header_re.search(buf, i + 1)
                j = m.start() if m else n
                rejected += j - i
                i = j
                continue
            end = i + length
            if end > n:
                break           # wait for the rest of this candidate
            if (sum(buf[i:end - 2]) & 0xFFFF) == (buf[end - 2] << 8 | buf[end - 1]):
                if i != expect:
                    resyncs += 1
                out.append(bytes(buf[i:end]))
                i = expect = end
                continue
            if i == expect:
                # A damaged packet where one was due; the next one is due after it.
                stats.bad_checksums += 1
                expect = end
            rejected += 1
            i += 1
        # (Counters kept in locals in the loop: this runs on every read of the port.)
        stats.packets += len(out)
        stats.rejected_bytes += rejected
        stats.resyncs += resyncs
        del buf[:i]
        self._base = base + i
        self._expect = base + expect
        return out

    def flush(self):
        """
        End of stream: return the good packets still buffered; count the rest as rejected.

        A header-like byte in junk near the end (or inside a damaged packet) announces a packet
        that reaches past the last byte; :meth:`feed` waits for the rest of it, holding back
        any good packets behind it.  No more bytes will come, so that candidate is rejected
        one byte at a time and the packets behind it are framed as usual.
        """
        out = []
        while self._buf:
            out += self.feed(b'')
            if self._buf:       # the first byte announces a packet longer than what is left
                self.stats.rejected_bytes += 1
                del self._buf[:1]
                self._base += 1
        self.reset()
        return out


def parse_bytes(data, codes=None):
    """Parse a complete byte string; return ``(packets, stats)``."""
    parser = StreamParser(codes)
    packets = parser.feed(data) + parser.flush()
    return packets, parser.stats
