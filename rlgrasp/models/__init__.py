"""The networks: state MLPs (``mlp``), camera encoders and camera actors (``cnn``), and the sizes of a
camera env's observation (``spec``). Below the training core, so that training, checkpoints,
evaluation and the camera learners all build them from here."""
