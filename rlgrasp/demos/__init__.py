"""Demonstrations for sparse rewards: recording (``record``), the file (``dataset``) and learning
from them (``bc``: behaviour-cloning pre-training and the DAPG imitation term of the PPO update)."""
