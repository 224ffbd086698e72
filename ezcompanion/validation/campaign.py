"""A validation campaign: seeded chunks of runs, on a Dask cluster or in process, merged.

Run i's engagement depends only on the seed and i (``scenarios.draw_scenarios``), and its
result only on its engagement (``batch``, ``oracle``), so the merged result is the same for
any chunk size, worker count or cluster. Each chunk is one task: draw, escape label,
oracle, every policy's flight; the failure map and the chattering sample are tasks too.

Where the tasks run (``CampaignSpec``): ``workers=1`` runs them here, in this process, on
all of numba's threads; otherwise on Dask (``distributed``): an existing cluster at
``scheduler`` (``tcp://host:8786``), or a ``LocalCluster`` on loopback with ``workers``
single-threaded worker processes (default one per core), numba held to one thread each
so that they do not oversubscribe the cores. The cluster's workers must have this package
installed, and the same (``provenance``: a worker that would compute otherwise, other
sources or another numba, is refused before any task, and any result from one as it comes
back); the results come back in submission order whatever order they finish in.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ezcompanion.config import load_scenario
from ezcompanion.errors import ConfigError
from ezcompanion.guidance import GuidanceParams
from ezcompanion.validation.abandon import AbandonChecker
from ezcompanion.validation.batch import AbandonCheck, BatchSettings, RunMetrics, simulate_batch
from ezcompanion.validation.chatter import Chattering, chattering
from ezcompanion.validation.escape import escape_margin_m
from ezcompanion.validation.fixed import ring_scenarios
from ezcompanion.validation.oracle import OracleResult, OracleSettings, run_oracle
from ezcompanion.validation.policies import POLICIES, make_policy
from ezcompanion.validation.provenance import mismatches, numerics
from ezcompanion.validation.scenarios import (
    _KIND_RING,
    ScenarioBatch,
    ScenarioDistribution,
    draw_scenarios,
)

__all__ = ["POLICIES", "CampaignResult", "CampaignSpec", "MapResult", "run_campaign"]

FloatArray = npt.NDArray[np.float64]

MAP_SCENARIO = Path(__file__).resolve().parents[2] / "config" / "paper_scenario1.yaml"


@dataclass(frozen=True, kw_only=True)
class CampaignSpec:
    """What to run: ``runs`` engagements from ``seed`` under each of ``policies``, a
    failure map of ``map_runs`` starts around the paper's layout (0: none), the oracle
    (``oracle``), the chattering sample (the first ``chatter_runs`` runs at 20 ms and 2 ms)
    and the abandon check (``abandon``, from the guidance side; None: not checked).
    Where: ``workers`` (1: in process; 0: one per core) or an existing ``scheduler``."""

    runs: int = 10_000
    seed: int = 0
    policies: tuple[str, ...] = POLICIES
    params: GuidanceParams = field(default_factory=GuidanceParams)
    distribution: ScenarioDistribution = field(default_factory=ScenarioDistribution)
    settings: BatchSettings = field(default_factory=BatchSettings)
    map_runs: int = 2000
    workers: int = 0  # 0: as many as cores and chunks allow
    chunk_runs: int = 2500
    scheduler: str | None = None
    oracle: bool = True
    oracle_settings: OracleSettings = field(default_factory=OracleSettings)
    chatter_runs: int = 0
    abandon: AbandonCheck | None = None

    def __post_init__(self) -> None:
        for name in ("runs", "chunk_runs"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(name, value, "must be an integer >= 1")
        for name in ("map_runs", "workers", "seed", "chatter_runs"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 0:
                raise ConfigError(name, value, "must be an integer >= 0")
        if not self.policies or any(p not in POLICIES for p in self.policies):
            raise ConfigError("policies", self.policies, f"must be some of {POLICIES}")
        if self.scheduler is not None and not self.scheduler.strip():
            raise ConfigError("scheduler", self.scheduler, "must be an address like tcp://h:8786")

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
    oracle: OracleResult | None = None


@dataclass(frozen=True, eq=False)
class CampaignResult:
    """The merged campaign: engagements, escape labels, the oracle, outcomes per policy."""

    spec: CampaignSpec
    scenarios: ScenarioBatch
    escape_margin_m: FloatArray
    metrics: dict[str, RunMetrics]
    map: MapResult | None
    wall_s: float
    oracle: OracleResult | None = None
    chattering: tuple[Chattering, ...] = ()
    cluster: str = "in process"


@dataclass(frozen=True, eq=False)
class _Chunk:
    scenarios: ScenarioBatch
    escape_margin_m: FloatArray
    oracle: OracleResult | None
    metrics: dict[str, RunMetrics]


def _fly(spec: CampaignSpec, scenarios: ScenarioBatch) -> dict[str, RunMetrics]:
    return {
        name: simulate_batch(
            scenarios,
            make_policy(name, scenarios, spec.params),
            accel_max_m_s2=spec.params.accel_max_m_s2,
            settings=spec.settings,
            abandon=spec.abandon,
            params=spec.params,
        )
        for name in spec.policies
    }


def _oracle(spec: CampaignSpec, scenarios: ScenarioBatch) -> OracleResult | None:
    if not spec.oracle:
        return None
    return run_oracle(
        scenarios,
        spec.params,
        settings=spec.oracle_settings,
        duration_s=spec.settings.duration_s,
        abandon=spec.abandon.profile if isinstance(spec.abandon, AbandonChecker) else None,
    )


def _run_chunk(spec: CampaignSpec, start: int, stop: int) -> _Chunk:
    scenarios = draw_scenarios(spec.distribution, spec.seed, start, stop)
    escape = escape_margin_m(scenarios, spec.params, dt_s=spec.settings.dt_s)
    return _Chunk(scenarios, escape, _oracle(spec, scenarios), _fly(spec, scenarios))


def _run_map(spec: CampaignSpec) -> MapResult:
    paper = load_scenario(MAP_SCENARIO)
    scenarios = ring_scenarios(
        paper.defenders, paper.target, runs=spec.map_runs, seed=spec.seed,
        speed_m_s=spec.distribution.speed_m_s,
        heading_error_max_deg=spec.distribution.heading_error_max_deg,
    ).with_response(spec.distribution, spec.seed, _KIND_RING)  # fmt: skip
    return MapResult(scenarios, _fly(spec, scenarios), _oracle(spec, scenarios))


def _run_chatter(spec: CampaignSpec) -> tuple[Chattering, ...]:
    scenarios = draw_scenarios(spec.distribution, spec.seed, 0, min(spec.chatter_runs, spec.runs))
    return tuple(
        chattering(scenarios, name, spec.params, duration_s=spec.settings.duration_s)
        for name in spec.policies
    )


def _in_worker() -> None:
    """Hold numba to one thread in a Dask worker (set before the first kernel runs)."""
    import numba

    numba.set_num_threads(1)


def _refuse(found: list[str], where: str) -> None:
    if found:
        more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
        raise ConfigError("scheduler", where, f"{found[0]}{more}: every worker must compute as "
                          "this process does, or the merged report is not this machine's")


def _attested(function: Callable[..., Any], *args: Any) -> tuple[str, dict[str, str], Any]:
    """``function(*args)`` run on a Dask worker, with the worker's address and what it
    computed with."""
    from distributed import get_worker

    return get_worker().address, numerics(), function(*args)


def _gather_attested(futures: list[Any], where: str,
                     report: Callable[[int, int], None]) -> list[Any]:  # fmt: skip
    """The tasks' results in submission order, each checked as it comes back to come from
    a worker that computes as this process does (a worker may join the cluster after the
    first check): on the first that does not, the tasks still to run are cancelled and the
    campaign refused."""
    from distributed import as_completed

    here = numerics()
    index = {future.key: i for i, future in enumerate(futures)}
    results: list[Any] = [None] * len(futures)
    arriving = as_completed(futures, with_results=True)  # type: ignore[no-untyped-call]
    for done, (future, (worker, seen, result)) in enumerate(arriving, start=1):
        i = index[future.key]
        found = mismatches(here, {f"{worker} (task {i})": seen})
        if found:
            for other in futures:
                other.cancel()
            _refuse(found, where)
        results[i] = result
        report(done, len(futures))
    return results


def _tasks(spec: CampaignSpec) -> list[tuple[str, Callable[..., Any], tuple[Any, ...]]]:
    tasks: list[tuple[str, Callable[..., Any], tuple[Any, ...]]] = [
        ("chunk", _run_chunk, (spec, a, b)) for a, b in spec.chunks()
    ]
    if spec.map_runs:
        tasks.append(("map", _run_map, (spec,)))
    if spec.chatter_runs:
        tasks.append(("chatter", _run_chatter, (spec,)))
    return tasks


def _run_here(spec: CampaignSpec, report: Callable[[int, int], None]) -> list[Any]:
    tasks = _tasks(spec)
    results = []
    for done, (_, function, args) in enumerate(tasks):
        results.append(function(*args))
        report(done + 1, len(tasks))
    return results


def _run_dask(spec: CampaignSpec, report: Callable[[int, int], None]) -> tuple[list[Any], str]:
    from distributed import Client, LocalCluster

    tasks = _tasks(spec)
    cluster: LocalCluster | None = None
    if spec.scheduler is None:
        workers = spec.workers or min(os.cpu_count() or 1, len(tasks))
        cluster = LocalCluster(  # type: ignore[no-untyped-call]
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            # no dashboard; its health routes on a free loopback port, not 8787
            scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
            env={"NUMBA_NUM_THREADS": "1"},
        )
        where = f"Dask LocalCluster, {workers} workers on 127.0.0.1"
    else:
        where = f"Dask cluster at {spec.scheduler}"
    try:
        address = cluster if cluster is not None else spec.scheduler
        with Client(address) as client:  # type: ignore[no-untyped-call]
            # every worker computes as this process does, or nothing is sent (provenance)
            _refuse(mismatches(numerics(), client.run(numerics, on_error="return")), where)
            client.run(_in_worker)
            futures = [
                client.submit(_attested, function, *args, pure=False, key=f"{kind}-{i}-{spec.seed}")
                for i, (kind, function, args) in enumerate(tasks)
            ]
            results = _gather_attested(futures, where, report)
    finally:
        if cluster is not None:
            cluster.close()
    return list(results), where


def run_campaign(
    spec: CampaignSpec, progress: Callable[[int, int], None] | None = None
) -> CampaignResult:
    """Run ``spec``; ``progress(done, total)`` is called with tasks as they finish."""
    started = time.monotonic()
    report = progress if progress is not None else (lambda done, total: None)
    if spec.scheduler is None and spec.workers == 1:
        results, where = _run_here(spec, report), "in process"
    else:
        results, where = _run_dask(spec, report)
    kinds = [kind for kind, _, _ in _tasks(spec)]
    parts: list[_Chunk] = [r for r, k in zip(results, kinds, strict=True) if k == "chunk"]
    ring = next((r for r, k in zip(results, kinds, strict=True) if k == "map"), None)
    chatter = next((r for r, k in zip(results, kinds, strict=True) if k == "chatter"), ())
    oracles = [p.oracle for p in parts]
    return CampaignResult(
        spec=spec,
        scenarios=ScenarioBatch.concat([p.scenarios for p in parts]),
        escape_margin_m=np.concatenate([p.escape_margin_m for p in parts]),
        metrics={n: RunMetrics.concat([p.metrics[n] for p in parts]) for n in spec.policies},
        map=ring,
        wall_s=time.monotonic() - started,
        oracle=OracleResult.concat([o for o in oracles if o is not None]) if spec.oracle else None,
        chattering=chatter,
        cluster=where,
    )
