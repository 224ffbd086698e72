#!/bin/sh
# Regenerates the numbers of docs/validation.md: every command and seed it quotes.
# Run from the repository root with the project installed (make .venv/.installed):
#   sh docs/validation/regenerate.sh            # the 10,000-run campaign and its figures
#   FULL=1 sh docs/validation/regenerate.sh     # also the 100,000-run campaigns (~10 + 30 min)
# Add SCHEDULER=tcp://host:8786 to run on an existing Dask cluster instead of a local one.
set -eu
BIN=${BIN:-.venv/bin}
OUT=${OUT:-validation-out}
WHERE=""
if [ -n "${SCHEDULER:-}" ]; then WHERE="--scheduler $SCHEDULER"; fi
# shellcheck disable=SC2086
"$BIN/ezcompanion" validate --runs 10000 --seed 2026 --map-runs 2000 --chatter-runs 100 \
    --no-progress --out "$OUT" $WHERE
cp "$OUT/summary.txt" "$OUT/tables.md" "$OUT"/*.png docs/validation/
# the default (backup) law against the robust law and the QP filter, 2,000 runs
# shellcheck disable=SC2086
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --law robust --law qp-filter \
    --map-runs 500 --chatter-runs 50 --abandon px4 --no-figures --no-progress \
    --out "$OUT-backup" $WHERE
mkdir -p docs/validation/backup_2k
cp "$OUT-backup/tables.md" "$OUT-backup/summary.txt" docs/validation/backup_2k/
# the default (backup) law alone, 10,000 runs of a seed none of the above used
# shellcheck disable=SC2086
"$BIN/ezcompanion" validate --runs 10000 --seed 2027 --law backup --map-runs 2000 \
    --chatter-runs 100 --abandon px4 --no-figures --no-progress --out "$OUT-backup-10k" $WHERE
mkdir -p docs/validation/backup_10k
cp "$OUT-backup-10k/tables.md" "$OUT-backup-10k/summary.txt" docs/validation/backup_10k/
# the default (backup) law as it runs by default (no abandon check), 10,000 runs of another
# fresh seed, the lower rungs in
# shellcheck disable=SC2086
"$BIN/ezcompanion" validate --runs 10000 --seed 2029 --law backup --map-runs 0 --chatter-runs 0 \
    --no-figures --no-progress --out "$OUT-backup-2029" $WHERE
mkdir -p docs/validation/backup_10k_2029
cp "$OUT-backup-2029/tables.md" "$OUT-backup-2029/summary.txt" docs/validation/backup_10k_2029/
# the abandon check measured only, then enforced (the law given PX4's profile), 600 runs
"$BIN/ezcompanion" validate --runs 600 --seed 2030 --law backup --map-runs 0 --chatter-runs 0 \
    --abandon px4 --no-figures --workers 1 --no-progress --out "$OUT-abandon-measured"
"$BIN/ezcompanion" validate --runs 600 --seed 2030 --law backup --set abandon_hold_s=1.15 \
    --set abandon_brake_m_s2=3.0 --map-runs 0 --chatter-runs 0 --abandon px4 --no-figures \
    --workers 1 --no-progress --out "$OUT-abandon-enforced"
for check in measured enforced; do
    mkdir -p "docs/validation/abandon_600/$check"
    cp "$OUT-abandon-$check/tables.md" "$OUT-abandon-$check/summary.txt" \
        "docs/validation/abandon_600/$check/"
done
# the shield's weight without and with its memory, the same 2,000 runs (no reserve)
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --set shield_weight_fall_1_s=0 \
    --set shield_robust_m=0 --map-runs 500 --chatter-runs 0 --abandon px4 --no-figures \
    --workers 1 --no-progress --out "$OUT-memory-off"
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --set shield_weight_fall_1_s=1 \
    --set shield_robust_m=0 --map-runs 500 --chatter-runs 0 --abandon px4 --no-figures \
    --workers 1 --no-progress --out "$OUT-memory-on"
for memory in off on; do
    mkdir -p "docs/validation/memory_2k/$memory"
    cp "$OUT-memory-$memory/tables.md" "$OUT-memory-$memory/summary.txt" \
        "docs/validation/memory_2k/$memory/"
done
# the shield's reserve (the default), the same 2,000 runs: against memory_2k/on, without it
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --map-runs 500 --chatter-runs 0 \
    --abandon px4 --no-figures --workers 1 --no-progress --out "$OUT-reserve"
mkdir -p docs/validation/reserve_2k
cp "$OUT-reserve/tables.md" "$OUT-reserve/summary.txt" docs/validation/reserve_2k/
# the same run since the held backup gives way to the least entry (docs/validation.md)
mkdir -p docs/validation/giveway_2k
cp "$OUT-reserve/tables.md" "$OUT-reserve/summary.txt" docs/validation/giveway_2k/
# the same, the law given the course rate as the service measures it (0.1 s filter)
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --set shield_robust_m=0 \
    --rate-filter 0.1 --map-runs 500 --chatter-runs 0 --abandon px4 --no-figures --workers 1 \
    --no-progress --out "$OUT-rate-filter-no_reserve"
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --rate-filter 0.1 \
    --map-runs 500 --chatter-runs 0 --abandon px4 --no-figures --workers 1 --no-progress \
    --out "$OUT-rate-filter-reserve"
for reserve in no_reserve reserve; do
    mkdir -p "docs/validation/rate_filter_2k/$reserve"
    cp "$OUT-rate-filter-$reserve/tables.md" "$OUT-rate-filter-$reserve/summary.txt" \
        "docs/validation/rate_filter_2k/$reserve/"
done
# the holds jittered, the law told the service's step (docs/validation.md, "A jittered stream")
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --map-runs 500 --chatter-runs 0 \
    --no-figures --workers 1 --no-progress --out "$OUT-jitter-0"
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --map-runs 500 --chatter-runs 0 \
    --no-figures --workers 1 --hold-jitter 0.1 --no-progress --out "$OUT-jitter-0.1"
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --map-runs 500 --chatter-runs 0 \
    --no-figures --workers 1 --hold-jitter 0.25 --no-progress --out "$OUT-jitter-0.25"
"$BIN/ezcompanion" validate --runs 2000 --seed 2026 --law backup --map-runs 500 --chatter-runs 0 \
    --no-figures --workers 1 --hold-jitter 0.4 --no-progress --out "$OUT-jitter-0.4"
for jitter in 0 0.1 0.25 0.4; do
    mkdir -p "docs/validation/jitter_2k/$jitter"
    cp "$OUT-jitter-$jitter/tables.md" "$OUT-jitter-$jitter/summary.txt" \
        "docs/validation/jitter_2k/$jitter/"
done
# the chattering ratio with the shield's reserve (the default) and without it, 100 runs
"$BIN/ezcompanion" validate --runs 100 --seed 2027 --law backup --map-runs 0 --chatter-runs 100 \
    --no-figures --workers 1 --no-progress --out "$OUT-chatter-reserve"
"$BIN/ezcompanion" validate --runs 100 --seed 2027 --law backup --set shield_robust_m=0 \
    --map-runs 0 --chatter-runs 100 --no-figures --workers 1 --no-progress \
    --out "$OUT-chatter-no_reserve"
for reserve in reserve no_reserve; do
    mkdir -p "docs/validation/chatter_100/$reserve"
    cp "$OUT-chatter-$reserve/tables.md" "$OUT-chatter-$reserve/summary.txt" \
        "docs/validation/chatter_100/$reserve/"
done
# the nominal's lead on a lag (docs/validation.md, "The nominal's lead"), off and on: the
# lagged clear-target runs at five ratios, the near-target runs, seed 2026's 10,000 with
# the exact course rate and with the service's measured one (~10 min in all)
"$BIN/ezcompanion" validate --runs 2000 --seed 2040 --law backup \
    --dist response_lag_s=1.0,1.4 --dist ideal_response_probability=0 \
    --dist target_near_probability=0 --map-runs 0 --chatter-runs 0 --no-figures \
    --set intercept_lead_ratio=0 --no-progress --out "$OUT-lead-clear-0"
"$BIN/ezcompanion" validate --runs 2000 --seed 2040 --law backup \
    --dist response_lag_s=1.0,1.4 --dist ideal_response_probability=0 \
    --dist target_near_probability=0 --map-runs 0 --chatter-runs 0 --no-figures \
    --set intercept_lead_ratio=0.25 --no-progress --out "$OUT-lead-clear-0.25"
"$BIN/ezcompanion" validate --runs 2000 --seed 2040 --law backup \
    --dist response_lag_s=1.0,1.4 --dist ideal_response_probability=0 \
    --dist target_near_probability=0 --map-runs 0 --chatter-runs 0 --no-figures \
    --set intercept_lead_ratio=0.5 --no-progress --out "$OUT-lead-clear-0.5"
"$BIN/ezcompanion" validate --runs 2000 --seed 2040 --law backup \
    --dist response_lag_s=1.0,1.4 --dist ideal_response_probability=0 \
    --dist target_near_probability=0 --map-runs 0 --chatter-runs 0 --no-figures \
    --set intercept_lead_ratio=0.75 --no-progress --out "$OUT-lead-clear-0.75"
"$BIN/ezcompanion" validate --runs 2000 --seed 2040 --law backup \
    --dist response_lag_s=1.0,1.4 --dist ideal_response_probability=0 \
    --dist target_near_probability=0 --map-runs 0 --chatter-runs 0 --no-figures \
    --set intercept_lead_ratio=1 --no-progress --out "$OUT-lead-clear-1"
"$BIN/ezcompanion" validate --runs 2000 --seed 2042 --law backup \
    --dist response_lag_s=0.2,1.4 --dist ideal_response_probability=0 \
    --dist target_near_probability=1 --map-runs 0 --chatter-runs 0 --no-figures \
    --set intercept_lead_ratio=0 --no-progress --out "$OUT-lead-near-0"
"$BIN/ezcompanion" validate --runs 2000 --seed 2042 --law backup \
    --dist response_lag_s=0.2,1.4 --dist ideal_response_probability=0 \
    --dist target_near_probability=1 --map-runs 0 --chatter-runs 0 --no-figures \
    --set intercept_lead_ratio=0.5 --no-progress --out "$OUT-lead-near-0.5"
"$BIN/ezcompanion" validate --runs 10000 --seed 2026 --law backup --map-runs 2000 \
    --chatter-runs 100 --no-figures --set intercept_lead_ratio=0 --no-progress \
    --out "$OUT-lead-2026-0"
"$BIN/ezcompanion" validate --runs 10000 --seed 2026 --law backup --map-runs 2000 \
    --chatter-runs 100 --no-figures --set intercept_lead_ratio=0.5 --no-progress \
    --out "$OUT-lead-2026-0.5"
"$BIN/ezcompanion" validate --runs 10000 --seed 2026 --law backup --rate-filter 0.1 \
    --map-runs 2000 --chatter-runs 0 --no-figures --set intercept_lead_ratio=0 --no-progress \
    --out "$OUT-lead-rate-filter-0"
"$BIN/ezcompanion" validate --runs 10000 --seed 2026 --law backup --rate-filter 0.1 \
    --map-runs 2000 --chatter-runs 0 --no-figures --set intercept_lead_ratio=0.5 \
    --no-progress --out "$OUT-lead-rate-filter-0.5"
for run in clear-0 clear-0.25 clear-0.5 clear-0.75 clear-1 near-0 near-0.5 2026-0 2026-0.5 rate-filter-0 rate-filter-0.5; do
    mkdir -p "docs/validation/lead/$run"
    cp "$OUT-lead-$run/tables.md" "$OUT-lead-$run/summary.txt" "docs/validation/lead/$run/"
done
if [ -n "${FULL:-}" ]; then
    # shellcheck disable=SC2086
    "$BIN/ezcompanion" validate --runs 100000 --seed 2026 --law robust --map-runs 10000 \
        --chatter-runs 0 --no-figures --no-progress --out "$OUT-100k" $WHERE
    cp "$OUT-100k/tables.md" docs/validation/tables_100k.md
    cp "$OUT-100k/summary.txt" docs/validation/summary_100k.txt
    # the default (backup) law at the same scale, with 10,000 failure-map starts (~30 min)
    # shellcheck disable=SC2086
    "$BIN/ezcompanion" validate --runs 100000 --seed 2026 --law backup --map-runs 10000 \
        --chatter-runs 0 --no-figures --no-progress --out "$OUT-backup-100k" $WHERE
    mkdir -p docs/validation/backup_100k
    cp "$OUT-backup-100k/tables.md" "$OUT-backup-100k/summary.txt" docs/validation/backup_100k/
    # and 10,000 runs of a fresh seed beside it, so that the oracle-safe runs number over
    # 100,000 (~4 min)
    # shellcheck disable=SC2086
    "$BIN/ezcompanion" validate --runs 10000 --seed 2031 --law backup --map-runs 0 \
        --chatter-runs 0 --no-figures --no-progress --out "$OUT-backup-2031" $WHERE
    mkdir -p docs/validation/backup_10k_2031
    cp "$OUT-backup-2031/tables.md" "$OUT-backup-2031/summary.txt" docs/validation/backup_10k_2031/
    # and a third seed, flown on 2026-12-07 (~2 min)
    # shellcheck disable=SC2086
    "$BIN/ezcompanion" validate --runs 10000 --seed 2033 --law backup --map-runs 0 \
        --chatter-runs 0 --no-figures --no-progress --out "$OUT-backup-2033" $WHERE
    mkdir -p docs/validation/backup_10k_2033
    cp "$OUT-backup-2033/tables.md" "$OUT-backup-2033/summary.txt" docs/validation/backup_10k_2033/
fi
