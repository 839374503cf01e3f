"""The learners on the training core (``rlgrasp.train.algorithm.Algorithm``), one package each: PPO
(``ppo``), SAC (``sac``), DAgger (``dagger``, ``algo=distill``). ``registry`` finds them; a new one is
a package here with an ``ALGORITHM`` entry and a ``configs/algo/<name>.yaml``. Light to import."""
