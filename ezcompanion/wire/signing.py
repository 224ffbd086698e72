"""MAVLink 2 signing: keys (hex or MAVProxy's passphrase) and a signature check that
verifies before it stores anything."""

from __future__ import annotations

import hashlib
import hmac
import time
from typing import Any

from ezcompanion.errors import ConfigError

#: 2015-01-01T00:00:00Z, MAVLink 2 signing's time origin
SIGNING_EPOCH_S = 1420070400
_NEW_STREAM_BEHIND_10US = 60 * 100_000  # a new signed stream may be a minute behind ours


def signing_key_from_hex(key_hex: str, *, field: str = "signing_key_hex") -> bytes:
    """A 32-byte MAVLink 2 signing key from 64 hex digits; ConfigError names ``field``."""
    try:
        key = bytes.fromhex(key_hex)
    except (TypeError, ValueError):
        raise ConfigError(field, key_hex, "must be 64 hexadecimal digits") from None
    if len(key) != 32:
        raise ConfigError(field, key_hex, "must be 64 hexadecimal digits (32 bytes)")
    return key


def signing_key_from_file(path: str, *, field: str = "signing_key_file") -> bytes:
    """A 32-byte signing key from a file holding 64 hex digits; ConfigError names ``field``
    and the path (never the file's content)."""
    try:
        with open(path, encoding="ascii") as source:
            text = source.read().strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(field, path, f"cannot be read: {exc}") from None
    try:
        return signing_key_from_hex(text)
    except ConfigError:
        raise ConfigError(field, path, "must hold 64 hexadecimal digits") from None


def signing_key_from_passphrase(passphrase: str) -> bytes:
    """The key MAVProxy's ``signing setup PASSPHRASE`` derives: SHA-256 of the UTF-8 text."""
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def signing_now_10us() -> int:
    """The present time as MAVLink 2 signing counts it (10 us since 2015)."""
    return int(max(time.time() - SIGNING_EPOCH_S, 0.0) * 1e5)


def signature_matches(key: bytes, msgbuf: bytes | bytearray) -> bool:
    """The signed frame ``msgbuf`` carries a signature made with ``key`` (SHA-256 of the key
    and the frame, the MAVLink 2 specification's; constant-time compare). Its timestamp is
    not judged here."""
    if len(msgbuf) < 13:  # link id, 6-byte timestamp, 6-byte signature
        return False
    digest = hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6]
    return hmac.compare_digest(digest, bytes(msgbuf[-6:]))


def check_signature_first(
    mav: Any, msgbuf: bytearray, src_system: int, src_component: int
) -> bool:
    """MAVLink 2 signature check that verifies before it stores anything.

    pymavlink 2.4.x stores the stream's timestamp before it compares the signature, so one
    frame with a wrong key and timestamp 2^48 makes every later genuine frame of that
    stream "old" for good. Here the signature is checked first; only a genuine frame can
    move a stream's timestamp (or the link's own). The timestamp rules are the spec's: a
    known stream must advance (no replay), a new stream may be at most a minute behind.
    """
    signing = mav.signing
    key = signing.secret_key
    if key is None or not signature_matches(bytes(key), msgbuf):
        return False
    tlow, thigh = mav.mav_sign_unpacker.unpack(msgbuf[-12:-6])
    timestamp = tlow + (thigh << 32)
    stream = (msgbuf[-13], src_system, src_component)
    last = signing.stream_timestamps.get(stream)
    if last is not None and timestamp <= last:
        return False  # a replay, or reordered
    if last is None and timestamp + _NEW_STREAM_BEHIND_10US < signing.timestamp:
        return False  # a new stream more than a minute behind
    signing.stream_timestamps[stream] = timestamp
    signing.timestamp = max(signing.timestamp, timestamp)
    return True
