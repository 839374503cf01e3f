"""TQC's config schema (``algo=tqc``: ``configs/algo/tqc.yaml`` names ``tqc_schema``) and its checks:
SAC's keys, with the critics' quantiles and how many of the pooled target's top ones are dropped."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from rlgrasp.algos.registry import Check
from rlgrasp.algos.sac import schema as sac


@dataclass
class TQCLossConfig(sac.SACLossConfig):
    """TQC's loss settings: SAC's, and the quantiles. The defaults are sb3-contrib's (25 quantiles a
    critic, 2 critics, the top 2 of each critic's share dropped: 46 of the 50 pooled atoms kept); the
    paper's 5 critics cost 2.5 times the critics' compute on a CPU for a bias a third of the drop
    already controls."""

    num_critics: int = 2
    n_quantiles: int = 25  # the atoms each critic outputs
    # Dropped from the pooled, sorted target atoms: this many per critic (the total is this x num_critics).
    top_quantiles_to_drop_per_net: int = 2


@dataclass
class TQCConfig(sac.SACConfig):
    """TQC (``rlgrasp.algos.tqc``): SAC with quantile critics and a truncated target; with ``demos``,
    demonstrations sampled beside online data as SAC's (RLPD)."""

    _target_: str = "rlgrasp.algos.tqc.TQC"  # the Algorithm class (rlgrasp.train.algorithm)
    name: str = "tqc"
    loss: TQCLossConfig = field(default_factory=TQCLossConfig)


SCHEMA = TQCConfig


def check(cfg: Any, batch: int, camera: Any) -> list[Check]:
    """SAC's checks, then the quantiles: at least one a critic, and a drop that keeps some of them."""
    loss = cfg.algo.loss
    n, drop = loss.n_quantiles, loss.top_quantiles_to_drop_per_net
    return [
        *sac.check(cfg, batch, camera),
        ("algo.loss.n_quantiles", n, n >= 1, "must be >= 1 (the atoms each critic outputs)"),
        (
            "algo.loss.top_quantiles_to_drop_per_net",
            drop,
            0 <= drop < max(n, 1),
            f"must be in [0, algo.loss.n_quantiles={n}): the target keeps (n_quantiles - drop) x "
            "num_critics atoms, and dropping n_quantiles or more per critic keeps none",
        ),
    ]
