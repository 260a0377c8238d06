"""Verdicts on clean simulated logs (the rate of 'unexplained structure', and of any effect
accepted) from the checkout at ROOT, for comparing a change with an older commit:

    git worktree add /tmp/old REV
    .venv/bin/python benchmarks/clean_verdicts.py /tmp/old mag 10
    .venv/bin/python benchmarks/clean_verdicts.py /tmp/old marg 10

Uses ROOT's calib_jax and ROOT's benchmarks/diagnosis_power.py simulations (the clean rows of
its ``mag`` part, both models, and its MARG tumble with no effect), one JSON line per noise
level and sample correlation. benchmarks/results/clean_verdicts_7300547.jsonl holds the
verdicts before the driver tests were prewhitened; the current rates are diagnosis_power.md's
last column."""

import json
import sys

root = sys.argv[1]
sys.path.insert(0, root)
sys.path.insert(0, root + "/benchmarks")
import diagnosis_power as dp  # noqa: E402

from calib_jax.diagnose import diagnose_marg  # noqa: E402

part, seeds = sys.argv[2], int(sys.argv[3])


def rates(diagnose, **row) -> None:
    """Print ``row`` with the rates of 'unexplained structure' and of any accepted effect
    over the seeds; ``diagnose(seed)`` gives one clean log's diagnosis."""
    found = [diagnose(seed) for seed in range(seeds)]
    unexplained = sum(d.verdict == "unexplained_structure" for d in found) / seeds
    effects = sum(bool(d.effects) for d in found) / seeds
    print(json.dumps(row | {"unexplained": unexplained, "effects": effects}), flush=True)


def mag_log(noise, corr, model):
    def diagnose(seed):
        s, raw, _ = dp.simulate_sensor("mag", None, 0.0, noise, corr, seed, model)
        return dp.diagnose_sensor("mag", None, s, raw, seed, model)

    return diagnose


def marg_log(noise, corr):
    def diagnose(seed):
        acc, mag = dp.simulate(seed, noise, corr)
        return diagnose_marg(acc, mag, sample_rate=dp.RATE, seed=seed, progress=False)

    return diagnose


for noise in ("low", "high"):
    for corr in ("independent", "correlated"):
        if part == "mag":
            for model in ("full", "sphere"):
                rates(mag_log(noise, corr, model), part="mag", model=model, noise=noise, corr=corr)
        else:
            rates(marg_log(noise, corr), part="marg", noise=noise, corr=corr)
