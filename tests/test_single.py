"""One vehicle's compiled step (``guidance.single``, the service's path) against the batch
path: the same law, actuator, shield and modes, to round-off, for every law."""

from __future__ import annotations

import ast
import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ezcompanion.config import load_scenario
from ezcompanion.errors import StateError
from ezcompanion.guidance import (
    GuidanceController,
    GuidanceStep,
    KinematicState,
    LawName,
    Target,
    _jit,
)
from ezcompanion.guidance._jit import (
    JIT_ENABLED,
    cache_dir,
    kernel_fingerprint,
    kernels_cached,
    python_sources,
)
from ezcompanion.guidance.backup import BACKUP_NONE
from ezcompanion.guidance.single import step_one
from ezcompanion.service import runner
from ezcompanion.service.events import EventKind, EventLog
from ezcompanion.service.runner import CompanionService
from ezcompanion.service.settings import companion_settings

CONFIG = Path(__file__).resolve().parents[1] / "config"
SCENARIO = load_scenario(CONFIG / "paper_scenario1.yaml")
LAWS = (LawName.PAPER, LawName.ROBUST, LawName.BACKUP)
STEP_FIELDS = [f.name for f in dataclasses.fields(GuidanceStep) if f.name != "law"]
LAW_FIELDS = ("h_m", "h_rate_m_s", "alpha", "accel_safety_m_s2", "accel_intercept_m_s2",
              "accel_desired_m_s2", "accel_desired_rate_m_s3", "accel_command_m_s2",
              "range_to_target_m", "lead_angle_target_rad", "bearing_to_target_rad",
              "margin_m", "clearance_m", "softmin_weight")  # fmt: skip


def random_states(rng: np.random.Generator, size: int, target: Target) -> KinematicState:
    """States all over the paper's layout, some inside the capture radius of the target."""
    north = rng.uniform(-4.0, 10.0, size)
    east = rng.uniform(-6.0, 6.0, size)
    near = rng.random(size) < 0.15
    north[near] = target.north_m + rng.uniform(-0.05, 0.05, near.sum())
    east[near] = target.east_m + rng.uniform(-0.05, 0.05, near.sum())
    return KinematicState(
        north_m=north,
        east_m=east,
        course_rad=rng.uniform(-math.pi, math.pi, size),
        speed_m_s=rng.uniform(0.5, 1.5, size),
        course_rate_rad_s=rng.uniform(-1.0, 1.0, size),
    )


def assert_same(single: GuidanceStep, batch: GuidanceStep, k: int) -> None:
    for name in STEP_FIELDS:
        one, many = getattr(single, name), getattr(batch, name)
        assert one.shape == () and one.dtype == many.dtype, name
        np.testing.assert_allclose(one, many[k], rtol=1e-12, atol=1e-12, err_msg=name)
    for name in LAW_FIELDS:
        one, many = getattr(single.law, name), getattr(batch.law, name)
        np.testing.assert_allclose(one, many[k], rtol=1e-12, atol=1e-12, err_msg=name)
    for name in ("reference_saturated", "command_limited"):
        assert getattr(single.law, name) == getattr(batch.law, name)[k], name


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("with_rate", [True, False])
@pytest.mark.parametrize("lag_s", [0.0, 0.8])
def test_one_vehicle_steps_like_its_row_of_a_batch(
    law: LawName, with_rate: bool, lag_s: float
) -> None:
    """Ten steps of 24 vehicles: the actuator, the model's flown acceleration, the held
    backup and the nominal's weight (its memory) carried from step to step in both paths;
    with a lag, the backup law's lead on it reads the same flown acceleration in both."""
    rng = np.random.default_rng(13 + int(with_rate))
    size = 24
    zones, target = SCENARIO.zones(), SCENARIO.target
    params = dataclasses.replace(SCENARIO.guidance, response_lag_s=lag_s)
    bound = params.accel_max_m_s2
    start = rng.uniform(-0.9 * bound, 0.9 * bound, size)
    batch = GuidanceController(zones=zones, target=target, params=params, law=law)
    batch.reset(start)
    singles = [GuidanceController(zones=zones, target=target, params=params, law=law)
               for _ in range(size)]  # fmt: skip
    for k, one in enumerate(singles):
        one.reset(float(start[k]))
    seen_modes: set[int] = set()
    for step in range(10):
        state = random_states(rng, size, target)
        if not with_rate:
            state = dataclasses.replace(state, course_rate_rad_s=None)
        dt_s = 0.02 if step % 3 else 0.05
        stepped = batch.step(state, dt_s)
        for k, one in enumerate(singles):
            rate = None if state.course_rate_rad_s is None else float(state.course_rate_rad_s[k])  # type: ignore[index]
            single = one.step_one(
                north_m=float(state.north_m[k]),  # type: ignore[index]
                east_m=float(state.east_m[k]),  # type: ignore[index]
                course_rad=float(state.course_rad[k]),  # type: ignore[index]
                speed_m_s=float(state.speed_m_s[k]),  # type: ignore[index]
                dt_s=dt_s,
                course_rate_rad_s=rate,
            )
            assert_same(single, stepped, k)
            seen_modes.add(int(single.mode))
        np.testing.assert_allclose(
            [one.accel_m_s2 for one in singles], batch.accel_m_s2, rtol=1e-12, atol=1e-12
        )
    assert len(seen_modes) >= 3  # the states reach capture, safety and interception alike


@settings(max_examples=40, deadline=None)
@given(
    north_m=st.floats(-6.0, 12.0),
    east_m=st.floats(-8.0, 8.0),
    course_rad=st.floats(-math.pi, math.pi),
    speed_m_s=st.floats(0.2, 3.0),
    accel_ratio=st.floats(-0.95, 0.95),
    law=st.sampled_from(LAWS),
)
def test_step_and_step_one_agree_with_a_batch_of_one(
    north_m: float, east_m: float, course_rad: float, speed_m_s: float, accel_ratio: float,
    law: LawName,
) -> None:  # fmt: skip
    """``step`` (one vehicle), ``step_one`` and a batch of one: the same step."""
    made = [GuidanceController(zones=SCENARIO.zones(), target=SCENARIO.target,
                               params=SCENARIO.guidance, law=law) for _ in range(3)]  # fmt: skip
    accel = accel_ratio * SCENARIO.guidance.accel_max_m_s2
    made[0].reset(accel)
    made[1].reset(accel)
    made[2].reset(np.array([accel]))
    by_step = made[0].step(KinematicState(north_m, east_m, course_rad, speed_m_s), 0.02)
    by_one = made[1].step_one(north_m=north_m, east_m=east_m, course_rad=course_rad,
                              speed_m_s=speed_m_s, dt_s=0.02)  # fmt: skip
    batch = made[2].step(KinematicState(north_m, east_m, course_rad, speed_m_s), 0.02)
    assert_same(by_step, batch, 0)
    assert_same(by_one, batch, 0)


def test_a_step_keeps_its_results_when_the_next_is_taken() -> None:
    c = GuidanceController(zones=SCENARIO.zones(), target=SCENARIO.target,
                           params=SCENARIO.guidance)  # fmt: skip
    c.reset()
    first = c.step_one(north_m=8.0, east_m=-4.0, course_rad=2.5, speed_m_s=1.0, dt_s=0.02)
    kept = {name: np.array(getattr(first, name)) for name in STEP_FIELDS}
    kept_h = float(first.law.h_m)
    second = c.step_one(north_m=2.3, east_m=2.0, course_rad=0.4, speed_m_s=1.0, dt_s=0.02)
    for name in STEP_FIELDS:
        np.testing.assert_array_equal(getattr(first, name), kept[name], err_msg=name)
    assert float(first.law.h_m) == kept_h != float(second.law.h_m)
    assert float(second.accel_lat_m_s2) == float(first.accel_lat_cmd_m_s2)


@pytest.mark.parametrize("field", ["north_m", "east_m", "course_rad", "speed_m_s"])
def test_step_one_refuses_a_non_finite_state_naming_the_field(field: str) -> None:
    values = {"north_m": 8.0, "east_m": -4.0, "course_rad": 2.5, "speed_m_s": 1.0,
              field: math.nan}  # fmt: skip
    c = GuidanceController(zones=SCENARIO.zones(), target=SCENARIO.target)
    c.reset(0.1)
    with pytest.raises(StateError) as caught:
        c.step_one(**values, dt_s=0.02)
    assert caught.value.field == field
    assert float(c.accel_m_s2) == 0.1  # nothing advanced


def test_step_one_refuses_what_step_refuses() -> None:
    c = GuidanceController(zones=SCENARIO.zones(), target=SCENARIO.target)
    c.reset()
    good = {"north_m": 8.0, "east_m": -4.0, "course_rad": 2.5}
    with pytest.raises(StateError, match="speed_m_s"):
        c.step_one(**good, speed_m_s=-1.0, dt_s=0.02)
    with pytest.raises(StateError, match="dt_s"):
        c.step_one(**good, speed_m_s=1.0, dt_s=math.inf)
    with pytest.raises(StateError, match="course_rate_rad_s"):
        c.step_one(**good, speed_m_s=1.0, dt_s=0.02, course_rate_rad_s=math.nan)
    with pytest.raises(StateError, match="north_m"):
        c.step_one(**{**good, "north_m": [8.0, 9.0]}, speed_m_s=1.0, dt_s=0.02)  # type: ignore[arg-type]
    # numbers that are not floats are taken as such
    as_int = c.step_one(north_m=8, east_m=-4, course_rad=2.5, speed_m_s=1, dt_s=0.02)
    assert math.isfinite(float(as_int.accel_lat_cmd_m_s2))
    batch = GuidanceController(zones=SCENARIO.zones(), target=SCENARIO.target)
    batch.reset(np.zeros(2))
    with pytest.raises(StateError, match="batch"):
        batch.step_one(**good, speed_m_s=1.0, dt_s=0.02)


def test_unshielded_laws_report_no_backup() -> None:
    for law in (LawName.PAPER, LawName.ROBUST):
        c = GuidanceController(zones=SCENARIO.zones(), target=SCENARIO.target, law=law)
        c.reset()
        step = c.step_one(north_m=8.0, east_m=-4.0, course_rad=2.5, speed_m_s=1.0, dt_s=0.02,
                          course_rate_rad_s=0.3)  # fmt: skip
        assert int(step.backup) == BACKUP_NONE
        assert math.isnan(float(step.shield_weight)) and math.isnan(float(step.certificate_m))


def test_the_kernel_cache_is_named_by_every_kernel_source(tmp_path: Path) -> None:
    """numba invalidates a cached kernel only when its own file changes; the one-vehicle
    step carries the shield's code from backup.py, so the cache directory is named by a
    digest of every source of the package: any edit there compiles afresh."""
    for name, text in (("law.py", "a = 1\n"), ("backup.py", "b = 2\n")):
        (tmp_path / name).write_text(text)
    before = kernel_fingerprint(tmp_path.glob("*.py"))
    assert kernel_fingerprint(tmp_path.glob("*.py")) == before
    (tmp_path / "backup.py").write_text("b = 3\n")
    changed = kernel_fingerprint(tmp_path.glob("*.py"))
    assert changed != before
    (tmp_path / "backup.py").write_text("b = 2\n")
    assert kernel_fingerprint(tmp_path.glob("*.py")) == before
    if not JIT_ENABLED:
        return
    from numba.core import config

    package = Path(_jit.__file__).parent
    here = kernel_fingerprint(python_sources(package))
    assert config.CACHE_DIR.endswith(f"numba-{here}")
    assert cache_dir("/elsewhere") == f"/elsewhere/numba-{here}"
    cache_path = step_one._cache._impl.locator.get_cache_path()  # type: ignore[attr-defined]
    assert cache_path.startswith(config.CACHE_DIR)


_KERNEL_DECORATORS = {"jit", "jit_borrow", "jit_inline", "jit_parallel"}
# where a kernel may take what it compiles in: its own module (numba's stamp of its file),
# the guidance package (the cache directory's digest), and these
_KERNEL_LIBRARIES = ("math", "numpy", "ezcompanion.guidance", "__future__", "typing",
                     "collections.abc", "numpy.typing")  # fmt: skip


def _kernels_foreign_names(source: str) -> list[str]:
    """The names the kernels of a module (its top-level functions decorated with one of
    ``_jit``'s decorators, by name, as ``_jit.jit`` or called) take from outside its own
    module, ``guidance/`` and ``_KERNEL_LIBRARIES``: a name imported at the top level from
    elsewhere (a relative import counts as elsewhere), or a top-level name assigned from
    one (numba freezes it as it was)."""
    tree = ast.parse(source)
    imported: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom):
            origin = "." * node.level + (node.module or "")
            for alias in node.names:
                imported[alias.asname or alias.name] = origin
        elif isinstance(node, ast.Import):
            for alias in node.names:
                imported[alias.asname or alias.name.split(".")[0]] = alias.name
    foreign = {name: origin for name, origin in imported.items()
               if not any(origin == lib or origin.startswith(lib + ".")
                          for lib in _KERNEL_LIBRARIES)}  # fmt: skip
    grew = True
    while grew:  # module constants made from a foreign name are foreign too
        grew = False
        for node in tree.body:
            if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None:
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                used = [n.id for n in ast.walk(node.value) if isinstance(n, ast.Name)]
                sources = [foreign[u] for u in used if u in foreign]
                for target in targets:
                    for name in (n.id for n in ast.walk(target) if isinstance(n, ast.Name)):
                        if sources and name not in foreign:
                            foreign[name], grew = sources[0], True
    found = []
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and any(map(_is_kernel_decorator,
                                                         node.decorator_list)):  # fmt: skip
            for used in ast.walk(node):
                if isinstance(used, ast.Name) and used.id in foreign:
                    found.append(f"{node.name}: {used.id} from {foreign[used.id]}")
    return found


def _is_kernel_decorator(decorator: ast.expr) -> bool:
    if isinstance(decorator, ast.Call):
        decorator = decorator.func
    name = decorator.attr if isinstance(decorator, ast.Attribute) else getattr(decorator, "id", "")
    return name in _KERNEL_DECORATORS


def test_kernels_outside_guidance_take_nothing_the_cache_would_not_see_change() -> None:
    """numba reloads a cached kernel while its own file is unchanged, and the cache
    directory is named by a digest of guidance/'s sources only. So a kernel elsewhere
    (validation/, service/) may compile in code and constants from its own module and from
    guidance/ only: a constant taken from a third file would stay frozen in the cache
    through an edit of that file. Every module that holds one is checked by its source
    (``_kernels_foreign_names`` says what it reads), and the check itself against a module
    that breaks the rule in each way it reads."""
    package = Path(_jit.__file__).parents[1]
    sources = {path: path.read_text() for path in python_sources(package, "**/*.py")
               if "guidance" not in path.relative_to(package).parts}  # fmt: skip
    holders = {path: text for path, text in sources.items()
               if "guidance._jit import" in text or "guidance import _jit" in text}  # fmt: skip
    assert {p.name for p in holders} >= {"_oracle_search.py", "escape.py", "identify.py"}
    for path, text in holders.items():
        assert _kernels_foreign_names(text) == [], path
    breaks = (
        "import math\n"
        "from ezcompanion.guidance import _jit\n"
        "from ezcompanion.guidance._jit import jit\n"
        "from ezcompanion.validation.scenarios import PAD_M\n"
        "from . import stats\n"
        "_TWICE = 2.0 * PAD_M\n"
        "@jit\n"
        "def kernel(x):\n"
        "    return math.hypot(x, PAD_M)\n"
        "@_jit.jit_borrow\n"
        "def other(x):\n"
        "    return x * _TWICE + stats.Z\n"
    )
    assert _kernels_foreign_names(breaks) == [
        "kernel: PAD_M from ezcompanion.validation.scenarios",
        "other: _TWICE from ezcompanion.validation.scenarios", "other: stats from .",
    ]


def test_a_cold_kernel_cache_is_seen_and_said_before_the_link_opens(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A first run after an install or an edit compiles the one-vehicle step (11 s idle,
    over a minute on a busy machine) before the link opens: the companion says so first,
    rather than sitting silent. The cache is seen cold exactly where numba has not indexed
    the kernel in a form numba would load; once this process has run the step it is warm."""
    assert kernels_cached(directory=str(tmp_path)) is not JIT_ENABLED  # uncompiled: "warm"
    controller = GuidanceController(zones=SCENARIO.zones(), target=SCENARIO.target)
    controller.reset()
    controller.step_one(north_m=8.0, east_m=-4.0, course_rad=2.5, speed_m_s=1.0, dt_s=0.02)
    assert kernels_cached()  # compiled (or loaded) here, so indexed
    if JIT_ENABLED:
        import pickle

        from numba.core import config

        (index,) = Path(config.CACHE_DIR).glob("guidance/single.step_one-*.nbi")
        copy = tmp_path / "guidance" / index.name
        copy.parent.mkdir()
        copy.write_bytes(index.read_bytes())  # the same index elsewhere: it loads
        assert kernels_cached(directory=str(tmp_path))
        assert not kernels_cached("guidance/backup.shield_one", directory=str(tmp_path))
        with index.open("rb") as stream:
            version = pickle.load(stream)
            stamp, overloads = pickle.loads(stream.read())

        def index_of(version: str, stamp: str, overloads: dict[object, str]) -> bytes:
            return pickle.dumps(version) + pickle.dumps((stamp, overloads))

        for stale in (b"", index_of("0.1", stamp, overloads),  # truncated; another numba
                      index_of(version, "an edited source", overloads),
                      index_of(version, stamp, {(k[0], ("another CPU",), k[2]): v
                                                for k, v in overloads.items()})):  # fmt: skip
            copy.write_bytes(stale)
            assert not kernels_cached(directory=str(tmp_path))
        copy.unlink()  # another Python's index of the kernel (a shared NUMBA_CACHE_DIR)
        other = copy.with_name(copy.name.replace(f".py{sys.version_info[0]}", ".py2"))
        other.write_bytes(index.read_bytes())
        assert other != copy and not kernels_cached(directory=str(tmp_path))
        other.rename(copy)
        assert kernels_cached(directory=str(tmp_path))
        # where numba cannot write its cache it keeps one elsewhere, and compiles there
        (tmp_path / "a-file").write_text("")
        assert not _jit._writable(tmp_path / "a-file" / "guidance")
        monkeypatch.setattr(_jit, "_writable", lambda directory: False)
        assert not kernels_cached(directory=str(tmp_path))
        monkeypatch.undo()

    settings_ = companion_settings(SCENARIO, connect="udpin:127.0.0.1:14550")
    said = []
    for cached in (False, True):
        monkeypatch.setattr(runner, "kernels_cached", lambda cached=cached: cached)
        events = EventLog()
        CompanionService(SCENARIO, settings_, events=events, telemetry=None)
        said.append([e.message for e in events.of_kind(EventKind.WARNING)
                     if "compiling the guidance kernels" in e.message])  # fmt: skip
    assert len(said[0]) == 1 and said[1] == []
