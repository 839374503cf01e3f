"""PPO training on TorchRL: configs, models, collection, update, checkpoints, logging.

Import the pieces from their modules (``rlgrasp.train.loop.train``,
``rlgrasp.train.checkpoint.policy_from_checkpoint``); this package stays light to import.
"""
