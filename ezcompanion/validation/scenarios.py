"""Random engagements drawn from documented distributions, as arrays for the batch.

Every draw is in a target-centred local NED frame (target at the origin: the law is
invariant under translation and rotation, so nothing is lost). One run:

1. **Start**: range ``start_range_m`` (uniform) from the target at a uniform bearing; course
   = line of sight to the target + a heading error uniform in +-``heading_error_max_deg``;
   speed ``speed_m_s``.
2. **Layout** (``Layout``): ``single`` (one defender), ``separate`` (2 to
   ``defenders_max``, no two nominal zones overlap) or ``overlap`` (2 to ``defenders_max``,
   each added defender overlaps one already placed, which makes the concave notches
   between zones), with probabilities ``layout_weights``. The nominal zone of a defender
   is the disc of its EZ radius at a 90 degree lead angle, rho(pi/2) = sqrt((R+c)^2 -
   (mu R)^2); two overlap when their centres are closer than the sum of those radii.
3. **Defenders**: speed ratio, range and capture radius uniform in their intervals.
   A placed defender sits at a fraction ``along_track`` of the way from the target to the
   start, offset across the line of sight by up to ``cross_track_max_m`` (so it threatens
   the straight path). Each further defender sits at ``overlap_ratio`` (``overlap``) or
   ``separate_ratio`` (``separate``) times the sum of the nominal radii from a defender
   already placed, in a uniform direction; a ``separate`` one must overlap none.
4. **Target class** (``TargetClass``), ``near`` with probability ``target_near_probability``:
   ``clear``: every defender at least rho(0) + ``target_clear_extra_m`` from the target,
   so the target is outside every zone for every heading. ``near``: the first defender at
   a uniform distance in [rho(pi) + ``near_floor_m``, rho(0)] from the target, in a uniform
   direction: the target is inside that zone for headings towards the defender (the
   paper's own target is such a case), and outside it for headings away.
5. **Start class** (``StartClass``), ``close`` with probability ``close_start_probability``:
   ``normal``: the start must have at least ``start_clearance_min_m`` of true clearance to
   every zone for its initial course. ``close``: the start is moved next to the first
   defender, at a lead angle to it uniform in +-``close_lead_max_deg`` and a true
   clearance uniform in ``close_clearance_m``: closing on a zone with little room, where
   the acceleration bound may make entry unavoidable (``escape.escape_margin_m`` tells).
   Its clearance to the other zones must be >= 0.
6. A geometry that fails its class's conditions is drawn again (the classes themselves are
   drawn once, so their shares are the configured ones).
7. **Vehicle response** (``response``): ideal with probability
   ``ideal_response_probability``, else a lag on the levels of ``response_lag_step_s`` in
   ``response_lag_s`` and a speed factor uniform in ``speed_factor``; from a stream of its
   own, so the geometry above is the same whatever the response.

Runs are drawn in blocks of ``BLOCK_RUNS`` from ``SeedSequence(seed, spawn_key=(kind,
block))``, so run i is the same whatever the chunking, worker count or total run count.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from enum import IntEnum

import numpy as np
import numpy.typing as npt

from ezcompanion.errors import ConfigError
from ezcompanion.guidance import Target, ZoneSet
from ezcompanion.validation.response import draw_response

__all__ = [
    "BLOCK_RUNS",
    "Layout",
    "ScenarioBatch",
    "ScenarioDistribution",
    "StartClass",
    "TargetClass",
    "clearance_m",
    "draw_scenarios",
    "ez_radius_m",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

BLOCK_RUNS = 1000
PAD_M = 1.0e6  # unused zone slots: defenders this far away weigh exactly 0 in the softmin
_KIND_RANDOM, _KIND_RING = 0, 1
_MAX_TRIES = 200


class Layout(IntEnum):
    """How the defenders sit relative to each other."""

    SINGLE = 0
    SEPARATE = 1
    OVERLAP = 2
    FIXED = 3  # a given layout (e.g. the paper's), starts drawn around it


class StartClass(IntEnum):
    """How the run starts relative to the zones."""

    NORMAL = 0
    CLOSE = 1


class TargetClass(IntEnum):
    """Where the target sits relative to the zones."""

    CLEAR = 0
    NEAR = 1


@dataclass(frozen=True, kw_only=True)
class ScenarioDistribution:
    """The distributions of a validation campaign; see the module docstring."""

    start_range_m: tuple[float, float] = (6.0, 10.0)
    heading_error_max_deg: float = 60.0
    speed_m_s: float = 1.0
    layout_weights: tuple[float, float, float] = (0.2, 0.3, 0.5)  # single, separate, overlap
    defenders_max: int = 4
    speed_ratio: tuple[float, float] = (0.5, 0.85)
    range_m: tuple[float, float] = (1.0, 2.0)
    capture_radius_m: tuple[float, float] = (0.2, 0.7)
    along_track: tuple[float, float] = (0.25, 0.75)
    cross_track_max_m: float = 3.0
    overlap_ratio: tuple[float, float] = (0.5, 0.95)
    separate_ratio: tuple[float, float] = (1.05, 1.6)
    target_near_probability: float = 0.3
    target_clear_extra_m: float = 0.5
    near_floor_m: float = 0.3
    start_clearance_min_m: float = 0.5
    close_start_probability: float = 0.1
    close_lead_max_deg: float = 45.0
    close_clearance_m: tuple[float, float] = (0.05, 0.5)
    # the vehicle's response (``ezcompanion.validation.response``)
    ideal_response_probability: float = 0.2
    response_lag_s: tuple[float, float] = (0.0, 1.4)
    response_lag_step_s: float = 0.2
    speed_factor: tuple[float, float] = (0.78, 1.0)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            values = value if isinstance(value, tuple) else (value,)
            if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
                raise ConfigError(f.name, value, "must be finite numbers")
            if any(v < 0.0 for v in values):
                raise ConfigError(f.name, value, "must be >= 0")
            if f.name != "layout_weights" and isinstance(value, tuple) and value[0] > value[1]:
                raise ConfigError(f.name, value, "must be an interval (low, high)")
        if not (self.speed_ratio[0] > 0.0 and self.speed_ratio[1] < 1.0):
            raise ConfigError("speed_ratio", self.speed_ratio, "must lie inside (0, 1)")
        if self.range_m[0] <= 0.0 or self.speed_m_s <= 0.0 or self.start_range_m[0] <= 0.0:
            raise ConfigError("range_m/speed_m_s/start_range_m", self, "must be > 0")
        if len(self.layout_weights) != len(Layout) - 1 or sum(self.layout_weights) <= 0.0:
            raise ConfigError("layout_weights", self.layout_weights, "three weights, sum > 0")
        if not isinstance(self.defenders_max, int) or self.defenders_max < 2:
            raise ConfigError("defenders_max", self.defenders_max, "must be an integer >= 2")
        if not 0.0 <= self.target_near_probability <= 1.0:
            raise ConfigError("target_near_probability", self.target_near_probability, "in [0, 1]")
        if not 0.0 <= self.close_start_probability <= 1.0:
            raise ConfigError("close_start_probability", self.close_start_probability, "in [0, 1]")
        if not 0.0 <= self.ideal_response_probability <= 1.0:
            raise ConfigError(
                "ideal_response_probability", self.ideal_response_probability, "in [0, 1]"
            )
        if not (self.speed_factor[0] > 0.0 and self.speed_factor[1] <= 1.0):
            raise ConfigError("speed_factor", self.speed_factor, "must lie inside (0, 1]")
        if self.heading_error_max_deg > 180.0:
            raise ConfigError("heading_error_max_deg", self.heading_error_max_deg, "<= 180")


@dataclass(frozen=True, eq=False)
class ScenarioBatch:
    """B engagements as arrays: starts (B,), zones (B, zones) padded far away, labels."""

    run_index: IntArray
    north_m: FloatArray
    east_m: FloatArray
    course_rad: FloatArray
    speed_m_s: FloatArray
    target_north_m: FloatArray
    target_east_m: FloatArray
    zone_north_m: FloatArray
    zone_east_m: FloatArray
    zone_range_m: FloatArray
    zone_capture_radius_m: FloatArray
    zone_speed_ratio: FloatArray
    defenders: IntArray
    layout: IntArray
    target_class: IntArray
    start_class: IntArray
    heading_error_rad: FloatArray
    response_lag_s: FloatArray  # tau of the vehicle's lag, commanded to flown a
    speed_factor: FloatArray  # flown speed over commanded (``speed_m_s``)
    response_class: IntArray  # ``response.ResponseClass``

    def __len__(self) -> int:
        return int(self.north_m.shape[0])

    def zones(self) -> ZoneSet:
        """One row of zones per run."""
        return ZoneSet.from_arrays(
            north_m=self.zone_north_m,
            east_m=self.zone_east_m,
            range_m=self.zone_range_m,
            capture_radius_m=self.zone_capture_radius_m,
            speed_ratio=self.zone_speed_ratio,
        )

    def targets(self) -> list[Target]:
        """One target per run, or a single one when every run shares it."""
        if (self.target_north_m == self.target_north_m[0]).all() and (
            self.target_east_m == self.target_east_m[0]
        ).all():
            return [
                Target(north_m=float(self.target_north_m[0]), east_m=float(self.target_east_m[0]))
            ]
        return [
            Target(north_m=float(n), east_m=float(e))
            for n, e in zip(self.target_north_m, self.target_east_m, strict=True)
        ]

    @property
    def flown_speed_m_s(self) -> FloatArray:
        """The speed the vehicle flies: commanded speed times the speed factor."""
        return self.speed_m_s * self.speed_factor

    @property
    def straight_line_time_s(self) -> FloatArray:
        """Start-to-target distance over the flown speed: a straight, unthreatened flight."""
        dn = self.target_north_m - self.north_m
        de = self.target_east_m - self.east_m
        return np.hypot(dn, de) / self.flown_speed_m_s

    def with_response(
        self, dist: ScenarioDistribution, seed: int, kind: int = _KIND_RANDOM
    ) -> ScenarioBatch:
        """The same runs with a vehicle response drawn per run (``response``)."""
        lag, factor, cls = draw_response(
            lag_s=dist.response_lag_s, lag_step_s=dist.response_lag_step_s,
            speed_factor=dist.speed_factor, ideal_probability=dist.ideal_response_probability,
            seed=seed, kind=kind, start=int(self.run_index.min()),
            stop=int(self.run_index.max()) + 1, block_runs=BLOCK_RUNS,
        )  # fmt: skip
        pick = self.run_index - self.run_index.min()
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values |= {"response_lag_s": lag[pick], "speed_factor": factor[pick]}
        return ScenarioBatch(**(values | {"response_class": cls[pick]}))

    def subset(self, index: IntArray | npt.NDArray[np.bool_]) -> ScenarioBatch:
        """The runs at ``index`` (integer positions or a mask)."""
        return ScenarioBatch(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @classmethod
    def concat(cls, batches: Sequence[ScenarioBatch]) -> ScenarioBatch:
        """Runs of several batches, in order (zone columns padded to the widest)."""
        width = max(b.zone_north_m.shape[1] for b in batches)
        parts: dict[str, list[npt.NDArray[np.generic]]] = {f.name: [] for f in fields(cls)}
        for batch in batches:
            pad = width - batch.zone_north_m.shape[1]
            for f in fields(cls):
                value = getattr(batch, f.name)
                if f.name.startswith("zone_") and pad:
                    fill = PAD_M if f.name in ("zone_north_m", "zone_east_m") else value[:, :1]
                    value = np.hstack([value, np.broadcast_to(fill, (len(batch), pad))])
                parts[f.name].append(value)
        return cls(**{name: np.concatenate(values) for name, values in parts.items()})


def ez_radius_m(
    speed_ratio: float | FloatArray,
    range_m: float | FloatArray,
    capture_radius_m: float | FloatArray,
    cos_sigma: float | FloatArray,
) -> FloatArray:
    """rho(sigma): the EZ boundary at lead angle sigma (given by its cosine)."""
    mu_r = np.asarray(speed_ratio) * range_m
    reach = np.asarray(range_m) + capture_radius_m
    cos_s = np.asarray(cos_sigma, dtype=np.float64)
    return np.asarray(mu_r * (cos_s + np.sqrt(cos_s**2 - 1.0 + (reach / mu_r) ** 2)))


def clearance_m(
    north_m: float,
    east_m: float,
    course_rad: float,
    defenders: FloatArray,
) -> FloatArray:
    """True clearance r - rho(sigma) to each defender row (north, east, R, c, mu)."""
    dn = defenders[:, 0] - north_m
    de = defenders[:, 1] - east_m
    r = np.hypot(dn, de)
    cos_sigma = (math.cos(course_rad) * dn + math.sin(course_rad) * de) / np.maximum(r, 1e-12)
    return r - ez_radius_m(defenders[:, 4], defenders[:, 2], defenders[:, 3], cos_sigma)


def _nominal_radius_m(row: FloatArray) -> float:
    """rho(pi/2) of a defender row (north, east, R, c, mu)."""
    return math.sqrt((row[2] + row[3]) ** 2 - (row[4] * row[2]) ** 2)


def _rho_0_pi_m(row: FloatArray) -> tuple[float, float]:
    """rho(0) and rho(pi): R + c + mu R and R + c - mu R."""
    return row[2] + row[3] + row[4] * row[2], row[2] + row[3] - row[4] * row[2]


def _overlaps(a: FloatArray, b: FloatArray) -> bool:
    gap = math.hypot(a[0] - b[0], a[1] - b[1])
    return gap < _nominal_radius_m(a) + _nominal_radius_m(b)


_Draw = tuple[FloatArray, FloatArray, int, int, int, float]


def _draw_one(rng: np.random.Generator, dist: ScenarioDistribution) -> _Draw:
    """One valid run: (start [n, e, course], defenders (k, 5), layout, target class,
    start class, heading error)."""
    weights = np.asarray(dist.layout_weights) / sum(dist.layout_weights)
    # the strata are drawn once, so their shares are the configured ones; only the
    # geometry is drawn again when it is invalid
    layout = Layout(int(rng.choice(3, p=weights)))
    count = 1 if layout is Layout.SINGLE else int(rng.integers(2, dist.defenders_max + 1))
    near = bool(rng.random() < dist.target_near_probability)
    close = bool(rng.random() < dist.close_start_probability)
    for _ in range(_MAX_TRIES):
        bearing = rng.uniform(-math.pi, math.pi)
        start_range = rng.uniform(*dist.start_range_m)
        start_n, start_e = start_range * math.cos(bearing), start_range * math.sin(bearing)
        heading_error = math.radians(rng.uniform(-1.0, 1.0) * dist.heading_error_max_deg)
        course = bearing + math.pi + heading_error
        rows = np.column_stack(
            [
                np.zeros((count, 2)),
                rng.uniform(*dist.range_m, count),
                rng.uniform(*dist.capture_radius_m, count),
                rng.uniform(*dist.speed_ratio, count),
            ]
        )
        if not _place(rng, dist, rows, layout, near, start_range, bearing):
            continue
        if close:
            start_n, start_e, course = _close_start(rng, dist, rows[0], start_n, start_e)
            line_of_sight = math.atan2(-start_e, -start_n)
            heading_error = math.remainder(course - line_of_sight, 2.0 * math.pi)
            clear = clearance_m(start_n, start_e, course, rows)
            valid = bool(clear[1:].min(initial=math.inf) >= 0.0)
        else:
            clear = clearance_m(start_n, start_e, course, rows)
            valid = bool(clear.min() >= dist.start_clearance_min_m)
        if valid:
            start = np.array([start_n, start_e, course])
            return start, rows, int(layout), int(near), int(close), heading_error
    raise ConfigError("distribution", dist, f"no valid engagement in {_MAX_TRIES} draws")


def _close_start(
    rng: np.random.Generator,
    dist: ScenarioDistribution,
    row: FloatArray,
    north_m: float,
    east_m: float,
) -> tuple[float, float, float]:
    """A start next to defender ``row``, on the side of (``north_m``, ``east_m``), closing
    on it at a small lead angle with a small true clearance."""
    away = math.atan2(east_m - row[1], north_m - row[0])  # from the defender to the start
    lead = math.radians(rng.uniform(-1.0, 1.0) * dist.close_lead_max_deg)
    gap = float(ez_radius_m(row[4], row[2], row[3], math.cos(lead))) + rng.uniform(
        *dist.close_clearance_m
    )
    north = row[0] + gap * math.cos(away)
    east = row[1] + gap * math.sin(away)
    return north, east, away + math.pi + lead


def _place(
    rng: np.random.Generator,
    dist: ScenarioDistribution,
    rows: FloatArray,
    layout: Layout,
    near: bool,
    start_range: float,
    bearing: float,
) -> bool:
    """Place ``rows``' defenders in place (columns 0, 1); False if no valid placement."""
    cos_b, sin_b = math.cos(bearing), math.sin(bearing)
    for k in range(rows.shape[0]):
        row = rows[k]
        rho_0, rho_pi = _rho_0_pi_m(row)
        for _ in range(50):
            if k == 0 and near:
                gap = rng.uniform(
                    rho_pi + dist.near_floor_m, max(rho_0, rho_pi + dist.near_floor_m)
                )
                angle = rng.uniform(-math.pi, math.pi)
                row[0], row[1] = gap * math.cos(angle), gap * math.sin(angle)
                break
            if k > 0 and layout is not Layout.SINGLE:
                anchor = rows[int(rng.integers(0, k))]
                ratio = dist.overlap_ratio if layout is Layout.OVERLAP else dist.separate_ratio
                gap = rng.uniform(*ratio) * (_nominal_radius_m(anchor) + _nominal_radius_m(row))
                angle = rng.uniform(-math.pi, math.pi)
                row[0] = anchor[0] + gap * math.cos(angle)
                row[1] = anchor[1] + gap * math.sin(angle)
            else:
                along = rng.uniform(*dist.along_track) * start_range
                across = rng.uniform(-1.0, 1.0) * dist.cross_track_max_m
                row[0] = along * cos_b - across * sin_b
                row[1] = along * sin_b + across * cos_b
            if math.hypot(row[0], row[1]) < rho_0 + dist.target_clear_extra_m:
                continue
            if layout is Layout.SEPARATE and any(_overlaps(row, rows[j]) for j in range(k)):
                continue
            break
        else:
            return False
    return True


def _block(dist: ScenarioDistribution, seed: int, kind: int, block: int) -> ScenarioBatch:
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(kind, block)))
    draws = [_draw_one(rng, dist) for _ in range(BLOCK_RUNS)]
    return _pack(draws, dist.defenders_max, dist.speed_m_s, block * BLOCK_RUNS)


def _pack(
    draws: Sequence[_Draw],
    width: int,
    speed_m_s: float,
    first_index: int,
    target: tuple[float, float] = (0.0, 0.0),
) -> ScenarioBatch:
    size = len(draws)
    zone = np.empty((5, size, width))
    zone[0:2] = PAD_M
    zone[2:] = np.array([1.0, 0.0, 0.5])[:, None, None]
    for k, (_, rows, *_labels) in enumerate(draws):
        zone[:, k, : rows.shape[0]] = rows.T
    starts = np.array([d[0] for d in draws])
    return ScenarioBatch(
        run_index=np.arange(first_index, first_index + size, dtype=np.int64),
        north_m=starts[:, 0].copy(),
        east_m=starts[:, 1].copy(),
        course_rad=starts[:, 2].copy(),
        speed_m_s=np.full(size, speed_m_s),
        target_north_m=np.full(size, target[0]),
        target_east_m=np.full(size, target[1]),
        zone_north_m=zone[0].copy(),
        zone_east_m=zone[1].copy(),
        zone_range_m=zone[2].copy(),
        zone_capture_radius_m=zone[3].copy(),
        zone_speed_ratio=zone[4].copy(),
        defenders=np.array([d[1].shape[0] for d in draws], dtype=np.int64),
        layout=np.array([d[2] for d in draws], dtype=np.int64),
        target_class=np.array([d[3] for d in draws], dtype=np.int64),
        start_class=np.array([d[4] for d in draws], dtype=np.int64),
        heading_error_rad=np.array([d[5] for d in draws]),
        response_lag_s=np.zeros(size),
        speed_factor=np.ones(size),
        response_class=np.zeros(size, dtype=np.int64),
    )


def draw_scenarios(dist: ScenarioDistribution, seed: int, start: int, stop: int) -> ScenarioBatch:
    """Runs ``start`` to ``stop`` (exclusive) of the campaign with ``seed``."""
    if not 0 <= start < stop:
        raise ConfigError("runs", (start, stop), "must be a non-empty range of run indices")
    blocks = range(start // BLOCK_RUNS, (stop - 1) // BLOCK_RUNS + 1)
    batch = ScenarioBatch.concat([_block(dist, seed, _KIND_RANDOM, b) for b in blocks])
    offset = blocks[0] * BLOCK_RUNS
    return batch.subset(np.arange(start - offset, stop - offset)).with_response(dist, seed)
