"""Warnings for a varied key that does not change the run: 100 identical runs say nothing.

Two ways to tell, the exact one first:
- From the scenario's semantics, before anything runs: a seed key (`SEED_KEYS`) seeds the lidar's
  range noise and nothing else, so it changes nothing where that noise is 0. When `lidar.noise` is
  0 at every point (the base scenario's value and not varied, or varied over zeros only), varying
  `lidar.seed`, or replicating with `--replicates`, gives identical runs.
- From the results, after the runs: runs that differ only in one key's value (the other keys and
  the replicate equal) and whose outcomes (reason, time, distance, clearance, ...) are all the
  same, for every such group, suggest that the key has no effect. Outcomes are a summary, not the
  signals: so this one says "may".
"""

from __future__ import annotations

from collections.abc import Sequence

from cosim.sweep.results import COMPLETED
from cosim.sweep.spec import NOISE_OF_SEED, SweepSpec


def _noise_is_zero_everywhere(spec: SweepSpec, noise_key: str, base_noise: float) -> bool:
    for dimension in spec.dimensions:
        if dimension.key == noise_key:
            values = dimension.values if dimension.values is not None else dimension.interval
            return all(isinstance(v, int | float) and not isinstance(v, bool) and v == 0 for v in values)
    return base_noise == 0


def seed_warnings(spec: SweepSpec, base_noise: dict[str, float]) -> list[str]:
    """Warnings for seed keys varied, or set by replicates, where their noise is 0 at every point.
    `base_noise` maps each noise key (`lidar.noise`) to its value in the base scenario."""
    warnings = []
    for dimension in spec.dimensions:
        noise_key = NOISE_OF_SEED.get(dimension.key)
        if noise_key is not None and _noise_is_zero_everywhere(spec, noise_key, base_noise[noise_key]):
            warnings.append(
                f"--vary {dimension.key}: {noise_key} is 0 in every run, and {dimension.key} only seeds "
                f"that noise: its values give identical runs (vary or --set {noise_key} > 0)"
            )
    for key in spec.seed_keys:
        noise_key = NOISE_OF_SEED[key]
        if _noise_is_zero_everywhere(spec, noise_key, base_noise[noise_key]):
            warnings.append(
                f"--replicates {spec.replicates}: {noise_key} is 0 in every run, and the replicates differ "
                f"only in {key}: the {spec.replicates} replicates of each point are identical runs "
                f"(--set {noise_key} > 0)"
            )
    return warnings


def outcome_warnings(
    rows: Sequence[dict[str, str]],
    keys: Sequence[str],
    group_keys: Sequence[str],
    outcome_keys: Sequence[str],
    skip: Sequence[str] = (),
) -> list[str]:
    """Warnings for each varied key (of `keys`, not in `skip`) whose values gave the same outcome in
    every group of completed runs equal in all other `group_keys`; a key is judged only when at
    least one group holds two of its values."""
    completed = [row for row in rows if row.get("status") == COMPLETED]
    warnings = []
    for key in keys:
        if key in skip:
            continue
        others = [other for other in group_keys if other != key]
        groups: dict[tuple[str, ...], list[dict[str, str]]] = {}
        for row in completed:
            groups.setdefault(tuple(row.get(other, "") for other in others), []).append(row)
        compared = [group for group in groups.values() if len({row.get(key) for row in group}) > 1]
        if not compared:
            continue
        if all(len({tuple(row.get(k) for k in outcome_keys) for row in group}) == 1 for group in compared):
            values = len({row.get(key) for row in completed})
            warnings.append(
                f"--vary {key}: its {values} values gave the same outcome (reason, time, distance, "
                f"clearance, ...) wherever the other keys were equal: it may have no effect on the run"
            )
    return warnings
