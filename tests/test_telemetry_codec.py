"""The telemetry payload formats: MessagePack and JSON decode to the same sample through the
one decoder, the schema travels inside the compact payload, and bad bytes are refused with
a ValueError (never anything else)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from ezcompanion.config import scenario_from_dict
from ezcompanion.records import TickCommand, VehicleState
from ezcompanion.service.loop import GuidanceLoop
from ezcompanion.telemetry.schema import (
    FORMATS,
    SCHEMAS,
    decode,
    encode,
    encoding_name,
    guidance_payload,
    state_payload,
)

CONFIG = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"


def ticks(count: int) -> list[TickCommand]:
    data = yaml.safe_load(CONFIG.read_text())
    data["target"] = {"north_m": -500.0, "east_m": 300.0}
    loop = GuidanceLoop(scenario_from_dict(data), loop_rate_hz=50.0, stale_after_s=1.0)
    out = []
    for k in range(count):
        t = 0.02 * k
        state = VehicleState(
            north_m=8.0 - 0.8 * t, east_m=-4.0 + 0.6 * t, down_m=-20.0,
            velocity_north_m_s=-0.8, velocity_east_m_s=0.6, yaw_rad=2.5,
            position_time_s=t, attitude_time_s=-math.inf, position_source="local",
        )  # fmt: skip
        command = loop.tick(state, t)
        assert isinstance(command, TickCommand)
        out.append(command)
    return out


COMMANDS = ticks(20)


@pytest.mark.parametrize("fmt", FORMATS)
def test_both_formats_decode_to_the_payload_the_service_built(fmt: str) -> None:
    for seq, command in enumerate(COMMANDS, start=1):
        for leaf, payload in (
            ("guidance", guidance_payload("v1", seq, command, 1.7e9, ("A", "B", "C"))),
            ("state", state_payload("v1", seq, command, 1.7e9)),
        ):
            raw = encode(leaf, payload, fmt)
            assert decode(raw, encoding_name(leaf, fmt)) == payload
    # the law's step beside the clock's (a period for a tick less than half a period on)
    assert [guidance_payload("v1", 1, c, 1.7e9, ())["law_dt_s"] for c in COMMANDS] == [
        c.law_dt_s for c in COMMANDS] and COMMANDS[-1].law_dt_s == pytest.approx(0.02)
    # an infinite age (no attitude yet) is null in both
    assert decode(encode("state", payload, fmt), encoding_name("state", fmt))[
        "attitude_age_s"
    ] is None


def test_the_compact_payload_is_smaller_and_carries_its_schema() -> None:
    payload = guidance_payload("v1", 1, COMMANDS[0], 1.7e9, ())
    compact, plain = encode("guidance", payload, "msgpack"), encode("guidance", payload, "json")
    assert len(compact) < len(plain)
    assert json.loads(plain) == payload
    assert SCHEMAS["guidance"].encode() in compact
    # the same bytes announced as another schema are refused: the schema is checked
    with pytest.raises(ValueError, match="schema"):
        decode(compact, encoding_name("state", "msgpack"))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_garbage_is_a_value_error_naming_the_problem(raw: bytes) -> None:
    for encoding in (encoding_name("guidance", "msgpack"), encoding_name("guidance", "json")):
        try:
            decode(raw, encoding)
        except ValueError as exc:
            assert str(exc)
