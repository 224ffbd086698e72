"""Chunked STATUSTEXT: the stub splits as ArduPilot and PX4 do, the companion joins them.

The two sides are written apart (``sitl_stub/status.py``, ``ezcompanion/service/
statustext.py``), so a round trip checks one against the other, through real frames.
"""

from __future__ import annotations

import string

from conftest_sitl import M
from hypothesis import given
from hypothesis import strategies as st

from ezcompanion.service.statustext import StatusTextAssembler
from sitl_stub.status import statustext_frames

_STUB = M.MAVLink(None, srcSystem=1, srcComponent=1)
_PARSER = M.MAVLink(None)


def frames(text: str, text_id: int = 7) -> list[object]:
    msgs = statustext_frames(_STUB, text, M.MAV_SEVERITY_WARNING, text_id)
    return [_PARSER.decode(bytearray(m.pack(_STUB))) for m in msgs]


def feed(assembler: StatusTextAssembler, msg: object, now_s: float = 0.0) -> list[str]:
    out = assembler.feed(str(msg.text), int(msg.severity), int(msg.id),  # type: ignore[attr-defined]
                         int(msg.chunk_seq), now_s)  # type: ignore[attr-defined]
    return [t.text for t in out]


@given(st.text(alphabet=string.ascii_letters + string.digits + " .,:-()", min_size=1,
               max_size=400))
def test_any_text_round_trips_as_one(text: str) -> None:
    assembler = StatusTextAssembler()
    got = [t for m in frames(text) for t in feed(assembler, m)]
    assert got == [text.rstrip("\0")]
    assert len(frames(text)) == (1 if len(text) <= 50 else len(text) // 50 + 1)


def test_interleaved_texts_and_a_lost_chunk() -> None:
    assembler = StatusTextAssembler(timeout_s=2.0)
    a, b = frames("A" * 120, text_id=1), frames("B" * 60, text_id=2)
    out = feed(assembler, a[0]) + feed(assembler, b[0]) + feed(assembler, b[1])
    assert out == ["B" * 60]
    out = feed(assembler, a[2], 0.5)  # a[1] lost: given out with the gap marked
    assert out == ["A" * 50 + "[...]" + "A" * 20]
    pending = frames("C" * 75, text_id=3)
    assert feed(assembler, pending[0], 1.0) == []
    late = feed(assembler, frames("short", text_id=0)[0], 3.5)
    assert late == ["C" * 50 + "[...]", "short"]
