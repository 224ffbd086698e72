"""Broken scenario files, generated, fed to both tools: ``ezcompanion simulate`` and
``sitl-stub``. Every one must end with exit code 2 and exactly one line on stderr that names
the broken field; never a traceback, never a run.

The generator breaks the paper's first scenario (with a ``sitl_stub:`` section for the stub)
in the ways issue 10 lists: wrong types, NaN, infinities and huge numbers (floats up to
1e308, integers up to 10**400), missing required keys, unknown keys, whole sections replaced,
binary junk, deep nesting and duplicate keys. Every value it writes is invalid by the
scenario's stated limits, so a tool that accepts one has a bug.
"""

from __future__ import annotations

import contextlib
import copy
import io
import re
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ezcompanion.cli import main as ezcompanion_main
from sitl_stub.cli import main as stub_main

CONFIG = Path(__file__).resolve().parents[1] / "config"
PAPER: dict[str, Any] = yaml.safe_load((CONFIG / "paper_scenario1.yaml").read_text())
STUB_SECTION: dict[str, Any] = {
    "profile": "copter",
    "connect": "udpout:127.0.0.1:14550",
    "system_id": 1,
    "seed": 0,
    "speedup": 1.0,
    "physics_dt_s": 0.01,
    "height_m": 20.0,
    "wind_north_m_s": 0.0,
    "start_armed": True,
    "initial_mode": "AUTO",
    "setpoint_timeout_s": 3.0,
    "streams": {"attitude_hz": 10.0, "local_position_ned_hz": 10.0},
    "faults": {"drop_rate": 0.0, "jump_north_m": 0.0, "freeze_mode": "silent"},
}
REQUIRED = {
    (): {"name", "vehicle", "target", "defenders"},
    ("vehicle",): {"north_m", "east_m", "speed_m_s", "accel_max_m_s2", "course_from_los_deg"},
    ("target",): {"north_m", "east_m"},
    ("defenders", "*"): {"north_m", "east_m", "range_m", "capture_radius_m", "speed_ratio"},
}
FREE_STRINGS = {"name", "signing_passphrase"}  # any string is valid there
NULLABLE = {"initial_mode", "setpoint_timeout_s"}  # null is valid there: the default
UNBOUNDED = {"seed"}  # any integer >= 0 is valid there: no huge positive one is broken
Path_ = tuple[str | int, ...]
Case = tuple[bytes, str | None]  # a file's bytes, and the field its error must name


def _leaves(node: Any, path: Path_ = ()) -> list[tuple[Path_, Any]]:
    if isinstance(node, dict):
        return [leaf for key, value in node.items() for leaf in _leaves(value, (*path, key))]
    if isinstance(node, list):
        return [leaf for i, value in enumerate(node) for leaf in _leaves(value, (*path, i))]
    return [(path, node)]


def _mappings(node: Any, path: Path_ = ()) -> list[Path_]:
    found: list[Path_] = []
    if isinstance(node, dict):
        found.append(path)
        for key, value in node.items():
            found += _mappings(value, (*path, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            found += _mappings(value, (*path, i))
    return found


def field_name(path: Path_) -> str:
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def _get(data: Any, path: Path_) -> Any:
    for part in path:
        data = data[part]
    return data


def base(tool: str) -> dict[str, Any]:
    data = copy.deepcopy(PAPER)
    if tool == "sitl-stub":
        data["sitl_stub"] = copy.deepcopy(STUB_SECTION)
    return data


words = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=12)
huge = st.one_of(
    st.floats(min_value=1e8, max_value=1e308),
    st.floats(min_value=-1e308, max_value=-1e8),
    st.integers(min_value=10**8, max_value=10**400),
    st.integers(min_value=-(10**400), max_value=-(10**8)),
)
non_finite = st.sampled_from([float("nan"), float("inf"), float("-inf")])
containers = st.one_of(
    st.lists(st.integers(0, 9), max_size=3), st.dictionaries(words, st.integers(0, 9), max_size=2)
)
not_a_number = st.one_of(words, st.booleans(), st.none(), containers)
not_a_string = st.one_of(st.integers(-5, 5), st.floats(-1.0, 1.0), st.none(), containers)


def bad_value(leaf: Path_, value: Any) -> st.SearchStrategy[Any]:
    """Values that are invalid for ``leaf`` whose valid value is ``value``."""
    if leaf[-1] in NULLABLE:
        return bad_value((*leaf[:-1], ""), value).filter(lambda v: v is not None)
    if isinstance(value, bool):
        return st.one_of(st.integers(0, 1), words, st.none())
    if isinstance(value, int | float):
        fractional = st.floats(0.1, 0.9) if isinstance(value, int) else st.nothing()
        too_big = huge.filter(lambda v: v < 0 or isinstance(v, float)) if (
            leaf[-1] in UNBOUNDED) else huge
        return st.one_of(too_big, non_finite, not_a_number, fractional)
    if leaf[-1] in FREE_STRINGS:
        return not_a_string
    # a name, an enum, an endpoint, a mode: non-strings, or words that are none of them
    return st.one_of(not_a_string, words.map(lambda w: f"{w} {w}"))


@st.composite
def broken_scenarios(draw: st.DrawFn, tool: str) -> Case:
    """The bytes of a broken scenario file, and the field the error must name (None: any)."""
    data = base(tool)
    kind = draw(st.sampled_from(
        ["value", "value", "value", "missing", "unknown", "section", "junk", "deep", "duplicate"]
    ))  # fmt: skip
    if kind == "value":
        stub_too = tool == "sitl-stub"
        leaves = [leaf for leaf in _leaves(data) if stub_too or leaf[0][0] != "sitl_stub"]
        leaf, value = draw(st.sampled_from(leaves))
        _get(data, leaf[:-1])[leaf[-1]] = draw(bad_value(leaf, value))
        return yaml.safe_dump(data).encode(), field_name(leaf)
    if kind == "missing":
        where, keys = draw(st.sampled_from(sorted(REQUIRED.items())))
        parent = tuple(draw(st.integers(0, 2)) if p == "*" else p for p in where)
        key = draw(st.sampled_from(sorted(keys)))
        del _get(data, parent)[key]
        expected = field_name((*parent, key)) if key != "course_from_los_deg" else "vehicle"
        return yaml.safe_dump(data).encode(), expected
    if kind == "unknown":
        where = draw(st.sampled_from([m for m in _mappings(data) if m[:1] != ("sitl_stub",)
                                      or tool == "sitl-stub"]))  # fmt: skip
        key = draw(words.filter(lambda w: w not in _get(data, where)))
        _get(data, where)[key] = 1.0
        return yaml.safe_dump(data).encode(), field_name((*where, key))
    if kind == "section":
        section = draw(st.sampled_from(["vehicle", "target", "defenders", "guidance", "origin"]))
        data[section] = draw(st.one_of(not_a_number.filter(lambda v: v != {}), st.just([])))
        if section == "defenders" and draw(st.booleans()):
            data[section] = [copy.deepcopy(PAPER["defenders"][0])] * draw(st.integers(65, 5000))
        return yaml.safe_dump(data).encode(), section
    if kind == "junk":
        return draw(st.binary(min_size=1, max_size=300)), None
    if kind == "deep":
        leaf, _ = draw(st.sampled_from(_leaves(data)))
        _get(data, leaf[:-1])[leaf[-1]] = "NEST_HERE"
        depth = draw(st.integers(17, 3000))
        text = yaml.safe_dump(data).replace("NEST_HERE", "[" * depth + "]" * depth)
        return text.encode(), None  # the leaf's path, or the file's as a whole when very deep
    # duplicate: one "key: value" line of the block-style file written twice
    lines = yaml.safe_dump(data, default_flow_style=False).splitlines()
    keyed = [i for i, line in enumerate(lines) if re.match(r"^\s*[a-z_0-9]+:", line)]
    i = draw(st.sampled_from(keyed))
    header = lines[i].rstrip().endswith(":")  # "vehicle:" opens a section: give it a value
    lines.insert(i, f"{lines[i]} 0" if header else lines[i])
    return ("\n".join(lines) + "\n").encode(), None


def check_refused(
    run: Callable[[list[str]], int], prog: str, argv: list[str], expected: str | None
) -> None:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = run(argv)
    text = err.getvalue()
    lines = text.splitlines()
    assert code == 2, (code, text, out.getvalue()[:500])
    assert len(lines) == 1, text
    assert lines[0].startswith(f"{prog}: error: "), text
    assert "Traceback" not in text and len(lines[0]) < 600, text
    if expected is not None:
        named = lines[0].removeprefix(f"{prog}: error: ").split(": ", 1)[0]
        assert expected.startswith(named) or named.startswith(expected), (expected, text)


FUZZ = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@FUZZ
@given(broken_scenarios("ezcompanion"))
def test_ezcompanion_refuses_every_broken_scenario_in_one_line(case: Case) -> None:
    content, expected = case
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scenario.yaml"
        path.write_bytes(content)
        check_refused(ezcompanion_main, "ezcompanion", ["simulate", str(path)], expected)


@FUZZ
@given(broken_scenarios("sitl-stub"))
def test_sitl_stub_refuses_every_broken_scenario_in_one_line(case: Case) -> None:
    content, expected = case
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scenario.yaml"
        path.write_bytes(content)
        argv = ["--config", str(path), "--duration", "1", "--connect", "udpout:127.0.0.1:9"]
        check_refused(stub_main, "sitl-stub", argv, expected)


def _alias_bomb(levels: int) -> str:
    """A YAML list of 9^levels leaves in a few hundred bytes (aliases of aliases)."""
    names = [f"a{k}" for k in range(levels)]
    parts = [f"&{names[0]} [{', '.join(['lol'] * 9)}]"]
    parts += [f"&{names[k]} [{', '.join([f'*{names[k - 1]}'] * 9)}]" for k in range(1, levels)]
    return f"[{', '.join(parts)}, *{names[-1]}]"


def test_an_alias_bomb_where_a_law_is_named_is_one_line_without_reading_it_whole() -> None:
    """A helper's YAML alias bomb (9^9 leaves) as `law:` ran out of memory (MemoryError,
    exit 70, 17 s under a 2 GB cap): the law's name was handed to the enum, whose error
    prints the value whole. Now refused as not a name, in one line; measured here with a
    bomb of 9^7 leaves (a repr of some 40 MB), by the memory its refusal takes."""
    import tracemalloc

    scenario = (CONFIG / "paper_scenario1.yaml").read_text()
    bomb = _alias_bomb(7)
    for key, old, new in (("law", "\nlaw: backup", f"\nlaw: {bomb}"),
                          ("guidance.blend", "\nguidance:", f"\nguidance:\n  blend: {bomb}"),
                          # (and the companion's, found by a reviewer)
                          ("companion.setpoint", "\nlaw: backup",
                           f"\nlaw: backup\ncompanion:\n  setpoint: {bomb}"),
                          ("companion.on_exit", "\nlaw: backup",
                           f"\nlaw: backup\ncompanion:\n  on_exit: {bomb}")):  # fmt: skip
        content = scenario.replace(old, new, 1)
        assert content != scenario
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "scenario.yaml"
            path.write_text(content)
            tracemalloc.start()
            try:
                argv = ["simulate", str(path)] if not key.startswith("companion") else [
                    "run", "--config", str(path), "--connect", "udpin:127.0.0.1:0",
                    "--no-telemetry", "--max-time", "0.5"]  # fmt: skip
                check_refused(ezcompanion_main, "ezcompanion", argv, key)
                _, peak = tracemalloc.get_traced_memory()
            finally:
                tracemalloc.stop()
        assert peak < 10_000_000, f"{key}: {peak / 1e6:.0f} MB to refuse it"
