"""Drive rlgrasp/PandaGrasp-v0 with an exported policy file alone (no training code, no TorchRL):
python examples/run_exported_policy.py <run>/export/policy.onnx|.pt2|.pt [episodes]

The JSON beside the file lists its inputs: a state policy reads the env's observation vector
(``observation``), a camera policy the env's ``state`` entry as ``observation`` plus its images
(``depth`` float32 metres, ``rgb`` uint8), each with a batch dimension in front."""

import json
import sys

import gymnasium as gym
import numpy as np

import rlgrasp  # noqa: F401  (registers the env id)

path, episodes = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 20
meta = json.load(open(path + ".json"))  # written beside the file by rlgrasp-export
names = [i["name"] for i in meta["inputs"]]  # in the file's argument order


def inputs(obs):
    """The env's observation as the file's inputs: name -> [1, ...] array of the declared dtype."""
    return {
        i["name"]: np.asarray(obs[i["env_key"]] if i["env_key"] else obs, i["dtype"])[None]
        for i in meta["inputs"]
    }


if path.endswith(".onnx"):
    import onnxruntime

    session = onnxruntime.InferenceSession(path)
    policy = lambda obs: session.run(None, inputs(obs))[0][0]  # noqa: E731
else:
    import torch

    net = torch.export.load(path).module() if path.endswith(".pt2") else torch.jit.load(path)
    # Positional, in the file's order: a torch.export module takes no keyword arguments.
    policy = lambda obs: net(*[torch.from_numpy(inputs(obs)[n]) for n in names]).detach().numpy()[0]  # noqa: E731
env, successes = gym.make(meta["env_id"], **meta["env_kwargs"]), 0  # the env it was trained in
for seed in range(episodes):  # the seeds rlgrasp-eval uses
    obs, info = env.reset(seed=seed)
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        done = terminated or truncated
    successes += bool(info["is_success"])  # success at the episode's end
print(f"success {successes}/{episodes} ({successes / episodes:.0%}) with {path}")
