"""Learned tuning against black-box tuning on machines the policy has not seen.

``held_out_machines`` draws machines from the randomiser with seeds far from those of
training (training environments use seeds ``seed … seed + n_envs - 1`` and their own
generator streams; held-out draws use ``HELD_OUT_SEED + k``). ``compare_policy_to_cma``
tunes each with CMA-ES (a generous budget) and with the policy (``policy_runs`` runs), and
reports both costs relative to the analytic design.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from envs.evaluation import Weights
from envs.randomize import MachineRandomizer
from tuning.cma_job import run_cma
from tuning.evaluator import Evaluator
from tuning.sb3_job import apply_policy
from twin.config import MachineConfig

__all__ = ["HELD_OUT_SEED", "compare_policy_to_cma", "held_out_machines"]

HELD_OUT_SEED = 1_000_003
"""First seed of the held-out machines."""


def held_out_machines(base: str | MachineConfig, count: int = 3) -> list[MachineConfig]:
    """``count`` random variants of ``base`` reserved for evaluation."""
    r = MachineRandomizer.of(base)
    return [r.sample(np.random.default_rng(HELD_OUT_SEED + k), name=f"held-out-{k}")
            for k in range(count)]


def compare_policy_to_cma(policy: Path, machines: list[MachineConfig], *,
                          program: str = "compact", cma_budget_s: float = 120.0,
                          cma_max_runs: int | None = None, policy_runs: int = 5,
                          workers: int = 2, weights: Weights | None = None,
                          seed: int = 0) -> list[dict[str, Any]]:
    """Per machine: ``{machine, analytic_cost, cma_cost, cma_runs, policy_cost,
    policy_runs, ratio, max_coordinate_error_um: {analytic, cma, policy}}`` where
    ``ratio = policy_cost / cma_cost`` (1.15 = the policy is 15 % worse)."""
    rows = []
    for cfg in machines:
        with Evaluator.create(cfg, program, weights=weights, workers=workers) as ev:
            cma_best = run_cma(ev, budget_s=cma_budget_s, max_evals=cma_max_runs, seed=seed)
            cma_runs = len(ev.trials)
        trials, base = apply_policy(policy, cfg, program=program, runs=policy_runs,
                                    weights=weights)
        pol = min([base, *trials], key=lambda t: t.cost)
        rows.append({
            "machine": cfg.name, "analytic_cost": base.cost, "cma_cost": cma_best.cost,
            "cma_runs": cma_runs, "policy_cost": pol.cost, "policy_runs": len(trials),
            "ratio": pol.cost / cma_best.cost,
            "max_coordinate_error_um": {
                "analytic": base.metrics["max_coordinate_error"] * 1e6,
                "cma": cma_best.metrics["max_coordinate_error"] * 1e6,
                "policy": pol.metrics["max_coordinate_error"] * 1e6},
        })
    return rows
