"""PPO (``algo=ppo``): clipped PPO with GAE on the training core, with its auxiliary terms.

``schema``: its config and checks; ``learner``: the update (``PPOLearner``: GAE, the clipped loss
over minibatches, the learning-rate schedule); ``algorithm``: the ``Algorithm`` the core builds
(``PPO``). This module stays light: the registry reads ``ALGORITHM`` without importing torch, and
``rlgrasp.algos.ppo.PPO`` (the class configs and checkpoints name) loads on first use.
"""

from rlgrasp.algos.registry import AlgorithmEntry, lazy_attributes

ALGORITHM = AlgorithmEntry(name="ppo", target="rlgrasp.algos.ppo.PPO", schema="rlgrasp.algos.ppo.schema")

__getattr__ = lazy_attributes(__name__, "rlgrasp.algos.ppo.algorithm")
