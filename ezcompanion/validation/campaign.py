"""A validation campaign: seeded chunks of runs, in parallel processes, merged in order.

Run i's engagement depends only on the seed and i (``scenarios.draw_scenarios``), and its
result only on its engagement (``batch``), so the merged result is the same for any chunk
size and worker count. Workers are separate processes (spawned, not forked: numba's
thread pool is not fork-safe), each with one numba thread, so that two of them fill two
cores without oversubscription; with one worker the chunks run here, on all threads.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass, field
from multiprocessing import get_context
from multiprocessing.sharedctypes import Synchronized
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ezcompanion.config import load_scenario
from ezcompanion.errors import ConfigError
from ezcompanion.guidance import GuidanceParams, LawName
from ezcompanion.validation.batch import (
    BatchSettings,
    Policy,
    RunMetrics,
    law_policy,
    simulate_batch,
)
from ezcompanion.validation.escape import escape_margin_m
from ezcompanion.validation.fixed import ring_scenarios
from ezcompanion.validation.qpfilter import QpFilterPolicy
from ezcompanion.validation.scenarios import (
    ScenarioBatch,
    ScenarioDistribution,
    draw_scenarios,
)

__all__ = ["POLICIES", "CampaignResult", "CampaignSpec", "MapResult", "run_campaign"]

FloatArray = npt.NDArray[np.float64]

POLICIES = ("paper", "robust", "qp-filter")
MAP_SCENARIO = Path(__file__).resolve().parents[2] / "config" / "paper_scenario1.yaml"


@dataclass(frozen=True, kw_only=True)
class CampaignSpec:
    """What to run: ``runs`` engagements from ``seed`` under each of ``policies``, and a
    failure map of ``map_runs`` starts around the paper's layout (0: none)."""

    runs: int = 10_000
    seed: int = 0
    policies: tuple[str, ...] = POLICIES
    params: GuidanceParams = field(default_factory=GuidanceParams)
    distribution: ScenarioDistribution = field(default_factory=ScenarioDistribution)
    settings: BatchSettings = field(default_factory=BatchSettings)
    map_runs: int = 2000
    workers: int = 0  # 0: as many as cores and chunks allow
    chunk_runs: int = 2500

    def __post_init__(self) -> None:
        for name in ("runs", "chunk_runs"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(name, value, "must be an integer >= 1")
        for name in ("map_runs", "workers", "seed"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 0:
                raise ConfigError(name, value, "must be an integer >= 0")
        if not self.policies or any(p not in POLICIES for p in self.policies):
            raise ConfigError("policies", self.policies, f"must be some of {POLICIES}")

    def chunks(self) -> list[tuple[int, int]]:
        """Run index ranges [start, stop) of the chunks."""
        return [
            (a, min(a + self.chunk_runs, self.runs)) for a in range(0, self.runs, self.chunk_runs)
        ]


@dataclass(frozen=True, eq=False)
class MapResult:
    """Starts drawn around the paper's layout, and each policy's outcomes from them."""

    scenarios: ScenarioBatch
    metrics: dict[str, RunMetrics]


@dataclass(frozen=True, eq=False)
class CampaignResult:
    """The merged campaign: engagements, escape labels and outcomes per policy."""

    spec: CampaignSpec
    scenarios: ScenarioBatch
    escape_margin_m: FloatArray
    metrics: dict[str, RunMetrics]
    map: MapResult | None
    wall_s: float


def _policy(name: str, scenarios: ScenarioBatch, params: GuidanceParams) -> Policy:
    if name == "qp-filter":
        return QpFilterPolicy(scenarios, params)
    return law_policy(scenarios, params, LawName(name))


_counter: Synchronized[int] | None = None


def _init_worker(counter: Synchronized[int] | None) -> None:
    global _counter
    _counter = counter
    import numba

    numba.set_num_threads(1)  # NUMBA_NUM_THREADS=1 is set too; this is belt and braces


def _tick(steps: int) -> None:
    if _counter is not None:
        with _counter.get_lock():
            _counter.value += steps


def _fly(
    spec: CampaignSpec, scenarios: ScenarioBatch, tick: Callable[[int], None]
) -> dict[str, RunMetrics]:
    return {
        name: simulate_batch(
            scenarios,
            _policy(name, scenarios, spec.params),
            accel_max_m_s2=spec.params.accel_max_m_s2,
            settings=spec.settings,
            progress=tick,
        )
        for name in spec.policies
    }


def _run_chunk(
    spec: CampaignSpec, start: int, stop: int
) -> tuple[ScenarioBatch, FloatArray, dict[str, RunMetrics]]:
    scenarios = draw_scenarios(spec.distribution, spec.seed, start, stop)
    escape = escape_margin_m(scenarios, spec.params, dt_s=spec.settings.dt_s)
    return scenarios, escape, _fly(spec, scenarios, _tick)


def _run_map(spec: CampaignSpec) -> MapResult:
    paper = load_scenario(MAP_SCENARIO)
    scenarios = ring_scenarios(
        paper.defenders, paper.target, runs=spec.map_runs, seed=spec.seed,
        speed_m_s=spec.distribution.speed_m_s,
        heading_error_max_deg=spec.distribution.heading_error_max_deg,
    )  # fmt: skip
    return MapResult(scenarios, _fly(spec, scenarios, _tick))


def run_campaign(
    spec: CampaignSpec, progress: Callable[[int, int], None] | None = None
) -> CampaignResult:
    """Run ``spec``; ``progress(done, total)`` is called with lockstep steps as they pass."""
    started = time.monotonic()
    chunks = spec.chunks()
    per_job = len(spec.policies) * (spec.settings.steps + 1)
    total = per_job * (len(chunks) + (1 if spec.map_runs else 0))
    workers = spec.workers or min(os.cpu_count() or 1, len(chunks) + (1 if spec.map_runs else 0))
    report = progress if progress is not None else (lambda done, total: None)
    if workers <= 1:
        done = [0]

        def tick(steps: int) -> None:
            done[0] += steps
            report(done[0], total)

        global _counter
        _counter = None
        parts = []
        for start, stop in chunks:
            scenarios = draw_scenarios(spec.distribution, spec.seed, start, stop)
            escape = escape_margin_m(scenarios, spec.params, dt_s=spec.settings.dt_s)
            parts.append((scenarios, escape, _fly(spec, scenarios, tick)))
        ring = None
        if spec.map_runs:
            paper = load_scenario(MAP_SCENARIO)
            scenarios = ring_scenarios(
                paper.defenders, paper.target, runs=spec.map_runs, seed=spec.seed,
                speed_m_s=spec.distribution.speed_m_s,
                heading_error_max_deg=spec.distribution.heading_error_max_deg,
            )  # fmt: skip
            ring = MapResult(scenarios, _fly(spec, scenarios, tick))
    else:
        context = get_context("spawn")
        counter = context.Value("q", 0)
        saved = os.environ.get("NUMBA_NUM_THREADS")
        os.environ["NUMBA_NUM_THREADS"] = "1"  # inherited by the workers, spawned on submit
        try:
            pool = ProcessPoolExecutor(
                workers, mp_context=context, initializer=_init_worker, initargs=(counter,)
            )
            map_future: Future[MapResult] | None = (
                pool.submit(_run_map, spec) if spec.map_runs else None
            )
            futures = [pool.submit(_run_chunk, spec, a, b) for a, b in chunks]
        finally:
            if saved is None:
                del os.environ["NUMBA_NUM_THREADS"]
            else:
                os.environ["NUMBA_NUM_THREADS"] = saved
        with pool:
            pending: list[Future[Any]] = [*futures]
            if map_future is not None:
                pending.append(map_future)
            while any(not f.done() for f in pending):
                time.sleep(0.2)
                report(int(counter.value), total)
            parts = [f.result() for f in futures]
            ring = map_future.result() if map_future is not None else None
        report(total, total)
    return CampaignResult(
        spec=spec,
        scenarios=ScenarioBatch.concat([p[0] for p in parts]),
        escape_margin_m=np.concatenate([p[1] for p in parts]),
        metrics={name: RunMetrics.concat([p[2][name] for p in parts]) for name in spec.policies},
        map=ring,
        wall_s=time.monotonic() - started,
    )
