"""Session-wide test settings and the fixtures shared by test modules: compose the train and eval
configs the way their scripts do, once, here; envs and scripts cleaned up after each test; a two-node
Ray cluster. Shared helpers that are not fixtures are in ``tests/helpers.py``."""

import os

import pytest

# Ray reads this once, when it is first imported (ray_private.ray_constants), and torchrl imports
# Ray as soon as any test module imports the collectors. Unset, Ray advertises the machine's network
# address for a cluster started on 127.0.0.1 and the driver never reaches it: the tests hang. The
# tests only ever start Ray on loopback, so keep it there for the whole session.
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")

from rlgrasp.compose import compose_eval, compose_train  # noqa: E402
from rlgrasp.envs import PandaGraspEnv
from tests.procs import Started, start_script  # noqa: E402


@pytest.fixture
def train_cfg(tmp_path):
    """``train_cfg(*overrides, run_dir=None)``: the training config, writing into ``tmp_path``."""

    def make(*overrides: str, run_dir=None):
        return compose_train([f"paths.output_dir={run_dir or tmp_path}", *overrides])

    return make


@pytest.fixture
def eval_cfg():
    """``eval_cfg(*overrides)``: the ``rlgrasp-eval`` config."""

    def make(*overrides: str):
        return compose_eval(list(overrides))

    return make


@pytest.fixture
def make_env():
    """``make_env(**kwargs)``: a ``PandaGraspEnv`` closed at the end of the test."""
    envs = []

    def _make(**kwargs):
        env = PandaGraspEnv(**kwargs)
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()


@pytest.fixture
def script(tmp_path):
    """``script(name, *args, cwd=tmp_path, env=None)``: ``python scripts/<name>.py`` started in its own
    process group (``tests.procs.Started``); whatever is left of each group is killed at the end."""
    started: list[Started] = []

    def start(name: str, *args: str, cwd=None, env=None) -> Started:
        out = tmp_path / f"{name}_{len(started)}.out"
        started.append(start_script(name, list(args), cwd or tmp_path, out, env))
        return started[-1]

    yield start
    for s in started:
        s.kill_group()


@pytest.fixture(scope="module")
def ray_cluster():
    """Two Ray nodes (one CPU each) on 127.0.0.1, the driver connected; torn down after the module."""
    pytest.importorskip("ray")  # on loopback: see RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER at the top
    import ray  # an optional extra, imported only once it is there
    from ray.cluster_utils import Cluster

    node = {"num_cpus": 1, "node_ip_address": "127.0.0.1"}
    cluster = Cluster(initialize_head=True, head_node_args={**node, "include_dashboard": False})
    try:
        cluster.add_node(**node)
        cluster.wait_for_nodes()
        ray.init(address=cluster.address, log_to_driver=False)
        yield cluster
    finally:
        ray.shutdown()
        cluster.shutdown()
