"""Campaigns on a Dask cluster, the vehicle's response in the batch, zero-count bounds,
chattering and the abandon hook."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from pathlib import Path

import numpy as np
import pytest

from ezcompanion.errors import ConfigError
from ezcompanion.guidance import GuidanceParams, KinematicState, LawName
from ezcompanion.guidance.abandon import ABANDON_PROFILES
from ezcompanion.validation.abandon import AbandonChecker
from ezcompanion.validation.batch import BatchSettings, StepResult, law_policy, simulate_batch
from ezcompanion.validation.campaign import (
    CampaignSpec,
    _attested,
    _gather_attested,
    run_campaign,
)
from ezcompanion.validation.chatter import chattering
from ezcompanion.validation.oracle import first_abandon_gap_m
from ezcompanion.validation.output import write_outputs
from ezcompanion.validation.policies import POLICIES
from ezcompanion.validation.provenance import _sources_digest, mismatches, numerics
from ezcompanion.validation.response import ResponseClass
from ezcompanion.validation.scenarios import ScenarioBatch, ScenarioDistribution, draw_scenarios
from ezcompanion.validation.stats import Rate, upper_bound_95

PARAMS = GuidanceParams()


# --- Dask --------------------------------------------------------------------------------


def _strip(report: dict) -> dict:  # type: ignore[type-arg]
    return {k: v for k, v in report.items() if k not in ("wall_s", "cluster")}


def test_a_local_dask_cluster_gives_the_in_process_report(tmp_path: Path) -> None:
    """The same seeded chunks on a 2-worker LocalCluster (loopback), on an existing cluster
    reached by its scheduler's address, and in this process: identical per-run arrays and
    identical reports, oracle included."""
    from distributed import LocalCluster

    spec = CampaignSpec(
        runs=14, seed=9, policies=("robust",), map_runs=4, chunk_runs=6, workers=1,
        settings=BatchSettings(duration_s=6.0), chatter_runs=1,
    )  # fmt: skip
    here = run_campaign(spec)
    dask = run_campaign(dataclasses.replace(spec, workers=2))
    assert here.cluster == "in process" and "LocalCluster, 2 workers" in dask.cluster
    with LocalCluster(
        n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None,
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
    ) as existing:  # fmt: skip
        address = existing.scheduler_address
        assert address.startswith("tcp://127.0.0.1:")
        remote = run_campaign(dataclasses.replace(spec, scheduler=address))
    assert remote.cluster == f"Dask cluster at {address}"
    np.testing.assert_array_equal(remote.metrics["robust"].min_clearance_m,
                                  here.metrics["robust"].min_clearance_m)  # fmt: skip
    assert here.oracle is not None and dask.oracle is not None
    np.testing.assert_array_equal(here.oracle.safe, dask.oracle.safe)
    np.testing.assert_array_equal(here.oracle.intercept, dask.oracle.intercept)
    for name, value in here.metrics["robust"].as_arrays().items():
        np.testing.assert_array_equal(value, dask.metrics["robust"].as_arrays()[name])
    reports = []
    for result, folder in ((here, "here"), (dask, "dask"), (remote, "remote")):
        write_outputs(result, tmp_path / folder, figures=False)
        reports.append(json.loads((tmp_path / folder / "report.json").read_text()))
    assert _strip(reports[0]) == _strip(reports[1]) == _strip(reports[2])
    assert reports[0]["numerics"] == numerics()  # what the runs were computed with
    assert reports[0]["machine"]["cpu"] and reports[0]["machine"]["cpu"] != "unknown"
    summary = (tmp_path / "here" / "summary.txt").read_text()
    assert f"numba {numerics()['numba']}, llvmlite " in summary.splitlines()[0]
    assert (tmp_path / "here" / "tables.md").read_text() == (
        tmp_path / "dask" / "tables.md"
    ).read_text()


def test_a_cluster_whose_workers_compute_otherwise_is_refused_before_any_run() -> None:
    """A worker that would compute the runs otherwise (here, its kernels uncompiled) is
    refused by name before any task goes out: the merged report would be neither its
    numbers nor this process's. A task's result from such a worker (one that joined after
    the check) is refused as it is gathered."""
    from distributed import Client, LocalCluster

    spec = CampaignSpec(runs=4, seed=9, policies=("robust",), map_runs=0, chunk_runs=2,
                        settings=BatchSettings(duration_s=2.0), chatter_runs=0)  # fmt: skip
    with LocalCluster(
        n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None,
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
        env={"EZCOMPANION_JIT": "0"},
    ) as uncompiled:  # fmt: skip
        address = uncompiled.scheduler_address
        with pytest.raises(ConfigError) as refused:
            run_campaign(dataclasses.replace(spec, scheduler=address))
        assert not uncompiled.scheduler.tasks  # nothing was submitted
        with Client(uncompiled) as client:
            tasks = [client.submit(_attested, math.hypot, 3.0, 4.0, pure=False),
                     client.submit(_attested, time.sleep, 60.0, pure=False)]  # fmt: skip
            assert client.gather(tasks[0])[2] == 5.0
            with pytest.raises(ConfigError, match=r"\(task 0\): kernels uncompiled"):
                _gather_attested(tasks, "that cluster", lambda done, total: None)
            assert tasks[1].status == "cancelled"  # what was still to run is not waited for
    message = str(refused.value)
    assert message.startswith("scheduler: worker tcp://127.0.0.1:")
    assert "kernels uncompiled (EZCOMPANION_JIT=0), where this process has compiled" in message
    assert f"(got 'Dask cluster at {address}')" in message


def test_a_mismatch_names_the_worker_the_field_and_both_values() -> None:
    here = numerics()
    assert set(here) == {"ezcompanion sources", "numpy", "numba", "llvmlite", "kernels", "python",
                         "libc"}
    older = dict(here, numba="0.67.0")
    assert mismatches(here, {"tcp://127.0.0.1:1": here, "tcp://127.0.0.1:2": older}) == [
        f"worker tcp://127.0.0.1:2: numba 0.67.0, where this process has {here['numba']}"]
    missing = {k: v for k, v in here.items() if k != "ezcompanion sources"}
    assert mismatches(here, {"w": missing}) == [
        f"worker w: ezcompanion sources unknown, where this process has "
        f"{here['ezcompanion sources']}"]
    assert mismatches(here, {"v": ModuleNotFoundError("No module named 'ezcompanion'")}) == [
        "worker v: cannot say what it computes with (ModuleNotFoundError: No module named "
        "'ezcompanion')"]


def test_kernels_run_uncompiled_either_way_are_named(tmp_path: Path) -> None:
    """``NUMBA_DISABLE_JIT=1`` runs the kernels uncompiled as ``EZCOMPANION_JIT=0`` does:
    each is named as such, not as compiled."""
    import subprocess
    import sys

    script = "from ezcompanion.validation.provenance import numerics; print(numerics()['kernels'])"
    for variable, value in (("NUMBA_DISABLE_JIT", "1"), ("EZCOMPANION_JIT", "0")):
        expected = f"uncompiled ({variable}={value})"
        env = {**os.environ, variable: value, "NUMBA_CACHE_DIR": str(tmp_path)}
        said = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                              text=True, timeout=120, check=True)  # fmt: skip
        assert said.stdout.strip() == expected


def test_the_sources_digest_reads_the_sources_only(tmp_path: Path) -> None:
    """An editor's lock file (a dangling link named ``.#x.py``) and macOS's ``._x.py`` are
    not sources: they neither break the digest nor change it; an edit of a source does."""
    package = tmp_path / "package"
    (package / "sub").mkdir(parents=True)
    (package / "sub" / "law.py").write_text("x = 1\n")
    before = _sources_digest(package)
    (package / "sub" / ".#law.py").symlink_to("user@host.1:1")
    (package / "._law.py").write_bytes(b"\0\5")
    assert _sources_digest(package) == before
    (package / "sub" / "law.py").write_text("x = 2\n")
    assert _sources_digest(package) != before


def test_every_law_is_a_policy() -> None:
    """A law added to LawName is validated by name with no other change."""
    assert set(POLICIES) == {law.value for law in LawName} | {"qp-filter"}


# --- the vehicle's response ----------------------------------------------------------


def test_response_draws_are_seeded_and_leave_the_geometry_alone() -> None:
    dist = ScenarioDistribution()
    whole = draw_scenarios(dist, 5, 0, 2000)
    part = draw_scenarios(dist, 5, 1500, 1600)
    np.testing.assert_array_equal(part.response_lag_s, whole.response_lag_s[1500:1600])
    np.testing.assert_array_equal(part.speed_factor, whole.speed_factor[1500:1600])
    ideal = whole.response_class == ResponseClass.IDEAL
    assert abs(ideal.mean() - 0.2) < 5 * math.sqrt(0.2 * 0.8 / 2000)
    assert (whole.response_lag_s[ideal] == 0.0).all() and (whole.speed_factor[ideal] == 1.0).all()
    lagged = whole.response_lag_s[~ideal]
    assert lagged.min() >= 0.0 and lagged.max() == pytest.approx(1.4)
    np.testing.assert_allclose(lagged / 0.2, np.round(lagged / 0.2), atol=1e-9)
    factor = whole.speed_factor[~ideal]
    assert factor.min() >= 0.78 and factor.max() <= 1.0
    # the geometry is the one drawn with no response at all
    none = draw_scenarios(dataclasses.replace(dist, ideal_response_probability=1.0), 5, 0, 2000)
    np.testing.assert_array_equal(none.north_m, whole.north_m)
    np.testing.assert_array_equal(none.zone_east_m, whole.zone_east_m)
    assert (none.response_lag_s == 0.0).all()


class _Steady:
    """A scripted policy: a constant lateral acceleration, recording what it is told."""

    def __init__(self, accel_m_s2: float, size: int) -> None:
        self.accel = np.full(size, accel_m_s2)
        self.rates: list[np.ndarray] = []
        self.speeds: list[np.ndarray] = []

    def step(self, state: KinematicState, dt_s: float) -> StepResult:
        assert state.course_rate_rad_s is not None
        self.rates.append(np.array(state.course_rate_rad_s, dtype=float))
        self.speeds.append(np.array(state.speed_m_s, dtype=float))
        size = self.accel.size
        return StepResult(self.accel, self.accel, np.ones(size), np.full(size, 9.0),
                          np.zeros(size, dtype=bool))  # fmt: skip

    def keep(self, scenarios: ScenarioBatch, mask: np.ndarray) -> _Steady:
        return self


def test_the_vehicle_flies_the_lagged_acceleration_at_its_speed() -> None:
    """A constant commanded a: the measured course rate is a (1 - exp(-t / tau)) / v_f,
    v_f = k v, and the vehicle turns at that rate (its course after T is the integral)."""
    batch = draw_scenarios(ScenarioDistribution(), 3, 0, 3)
    batch = dataclasses.replace(
        batch, response_lag_s=np.array([0.0, 0.6, 1.4]), speed_factor=np.array([1.0, 0.8, 0.9])
    )
    policy = _Steady(0.5, 3)
    simulate_batch(batch, policy, accel_max_m_s2=1.0, settings=BatchSettings(duration_s=3.0))
    t = np.arange(len(policy.rates)) * 0.02
    speed = batch.speed_m_s * batch.speed_factor
    for k, tau in enumerate(batch.response_lag_s):
        rates = np.array([r[k] for r in policy.rates])
        expected = 0.5 * (1.0 - np.exp(-t / tau)) if tau > 0.0 else np.full(t.size, 0.5)
        if tau == 0.0:
            expected[0] = 0.0  # at rest before the first command
        np.testing.assert_allclose(rates, expected / speed[k], atol=1e-9)
        assert policy.speeds[-1][k] == pytest.approx(speed[k])


def test_the_law_is_told_each_run_lag() -> None:
    batch = draw_scenarios(ScenarioDistribution(), 8, 0, 60)
    policy = law_policy(batch, PARAMS, LawName.ROBUST)
    lags = {float(c.params.response_lag_s): rows for rows, c in policy.groups}  # type: ignore[attr-defined]
    assert set(lags) == set(np.unique(batch.response_lag_s).tolist())
    for lag, rows in lags.items():
        assert (batch.response_lag_s[rows] == lag).all()


# --- statistics, chattering, abandon -------------------------------------------------


def test_zero_counts_report_their_one_sided_upper_bound() -> None:
    assert upper_bound_95(0, 100_000) == pytest.approx(2.9957e-5, rel=1e-4)  # < 0.003%
    assert upper_bound_95(0, 100_000) < 3e-5
    # Clopper-Pearson one-sided 95%, 1 of 10: 0.3942 (e.g. tables of the binomial)
    assert upper_bound_95(1, 10) == pytest.approx(0.3942, abs=5e-4)
    assert upper_bound_95(10, 10) == 1.0
    rate = Rate.of(np.zeros(100_000, dtype=bool))
    assert rate.percent() == "0/100000 (<0.0030%)"


def test_chattering_shows_a_stiff_loop_and_not_the_default() -> None:
    """The robust law's tracking loop at its default gain carries over from 2 ms to 20 ms;
    at k_track_m_s3 = 20 (gain K_a / phi = 400 /s, 8 per 20 ms step) it chatters at the
    coarse step only (issue 9: total variation 188 m/s^2 against 2)."""
    dist = dataclasses.replace(ScenarioDistribution(), ideal_response_probability=1.0)
    batch = draw_scenarios(dist, 2026, 0, 3)
    smooth = chattering(batch, "robust", PARAMS, duration_s=4.0)
    stiff = chattering(
        batch, "robust", dataclasses.replace(PARAMS, k_track_m_s3=20.0), duration_s=4.0
    )
    assert np.nanmax(smooth.ratio) < 1.5
    assert np.nanmedian(stiff.ratio) > 3.0
    assert "ratio median" in smooth.line()
    assert "; 0 of 3 runs above 1.5" in smooth.line()
    assert "; 3 of 3 runs above 1.5" in stiff.line()


def _never_safe(scenarios, state, accel_cmd_m_s2, params):  # type: ignore[no-untyped-def]
    return np.zeros(len(scenarios), dtype=bool)


def test_the_abandon_hook_counts_the_setpoints_it_rejects() -> None:
    batch = draw_scenarios(ScenarioDistribution(), 1, 0, 4)
    settings = BatchSettings(duration_s=3.0)
    m = simulate_batch(batch, law_policy(batch, PARAMS, LawName.ROBUST), accel_max_m_s2=1.0,
                       settings=settings, abandon=_never_safe, params=PARAMS)  # fmt: skip
    flown = np.rint(m.end_time_s / settings.dt_s).astype(int)
    np.testing.assert_array_equal(m.abandon_unsafe_steps, flown - 50 + 1)
    unchecked = simulate_batch(batch, law_policy(batch, PARAMS, LawName.ROBUST),
                               accel_max_m_s2=1.0, settings=settings)  # fmt: skip
    assert (unchecked.abandon_unsafe_steps == -1).all()


def test_the_report_splits_the_setpoints_not_safe_to_abandon_by_the_oracles_search(
    tmp_path: Path,
) -> None:
    """With PX4's abandon check the oracle also asks, per run, whether some manoeuvre makes
    the first checked setpoint safe to abandon (``first_abandon_gap_m``, the same gap as
    asked alone); the summary counts the runs holding a setpoint not safe to abandon both
    ways, and report.json gives the rate where the search found one. Without the check the
    gap is not asked (NaN) and no line is written."""
    spec = CampaignSpec(
        runs=8, seed=2030, policies=("robust",), map_runs=0, chatter_runs=0, workers=1,
        settings=BatchSettings(duration_s=4.0), abandon=AbandonChecker("px4"),
    )  # fmt: skip
    result = run_campaign(spec)
    assert result.oracle is not None
    alone, _ = first_abandon_gap_m(result.scenarios, PARAMS, ABANDON_PROFILES["px4"])
    np.testing.assert_array_equal(result.oracle.abandon_gap_m, alone)
    m = result.metrics["robust"]
    held = ~m.entered & (m.abandon_unsafe_steps > 0)
    possible = int(np.count_nonzero(held & (alone >= 0.0)))
    assert int(held.sum()) > 0  # the robust law does not check the path
    write_outputs(result, tmp_path, figures=False)
    summary = (tmp_path / "summary.txt").read_text(encoding="utf-8")
    assert (f"Abandon check: robust: of {int((~m.entered).sum())} runs that stayed out, "
            f"{int(held.sum())} hold a setpoint from the first second on that is not safe to "
            f"abandon; {possible} of them from starts where") in summary  # fmt: skip
    assert f"{int(held.sum()) - possible} where none of it does." in summary
    row = json.loads((tmp_path / "report.json").read_text(encoding="utf-8"))["strata"][0]
    checked = ~m.entered & (alone >= 0.0)
    assert row["abandon_ok_where_possible"]["count"] == int(
        np.count_nonzero(m.abandon_unsafe_steps[checked] == 0)
    )
    assert np.load(tmp_path / "runs.npz")["oracle_abandon_gap_m"].shape == (8,)
    plain = run_campaign(dataclasses.replace(spec, abandon=None))
    assert plain.oracle is not None and np.isnan(plain.oracle.abandon_gap_m).all()
    write_outputs(plain, tmp_path / "plain", figures=False)
    assert "Abandon check" not in (tmp_path / "plain" / "summary.txt").read_text(encoding="utf-8")
