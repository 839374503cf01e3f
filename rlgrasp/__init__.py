"""rlgrasp: parallel PPO training of a Franka Panda grasp-and-lift task in PyBullet."""

import gymnasium

ENV_ID = "rlgrasp/PandaGrasp-v0"

if ENV_ID not in gymnasium.registry:
    # The env truncates its own episodes (max_episode_steps is a constructor argument).
    gymnasium.register(ENV_ID, entry_point="rlgrasp.envs:PandaGraspEnv")

__version__ = "0.1.0"
