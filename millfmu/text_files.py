"""Reading a user's text file (scene, DEM scene, flowsheet): UTF-8, with the byte-order mark
that Windows editors write taken off, and where the bytes are not UTF-8 the place to say."""

from __future__ import annotations


class NotUtf8(ValueError):
    """Bytes that are not UTF-8: ``start`` (byte offset), ``line`` (1-based), ``reason``
    (the codec's) and ``bytes`` (up to four bytes from ``start``) for the caller's message."""

    def __init__(self, raw: bytes, e: UnicodeDecodeError):
        self.start, self.reason = e.start, e.reason
        self.line = raw.count(b"\n", 0, e.start) + 1
        self.bytes = raw[e.start:e.start + 4]
        super().__init__(f"not UTF-8 at byte {self.start} (line {self.line}): {self.reason}")


def utf8_text(raw: bytes) -> str:
    """``raw`` decoded as UTF-8 without a leading byte-order mark; NotUtf8 where it is not
    UTF-8."""
    try:
        return raw.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as e:
        raise NotUtf8(raw, e) from None
