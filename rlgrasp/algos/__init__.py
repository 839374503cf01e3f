"""The learners on the training core (``rlgrasp.train.algorithm.Algorithm``): PPO and SAC. DAgger,
which distills a camera student from a state teacher, lives with the cameras (``rlgrasp.vision``)."""
