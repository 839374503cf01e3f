"""Hindsight experience replay in SAC's replay (``algo.her``, rlgrasp.algos.sac.her): a relabelled row's
goal is where the object was after a later step of its own episode, never another's, even when the
episode spans batches and the ring has wrapped; its reward is the task's sparse rule for that goal; the
share relabelled is ``relabel_ratio``; a resumed run relabels what it reads back; what HER cannot serve
is refused in one line; and a short run trains end to end."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from rlgrasp.algos.sac import SAC
from rlgrasp.algos.sac.her import EPISODE_KEY, GoalLayout
from rlgrasp.compose import compose_train
from rlgrasp.config import ConfigError
from rlgrasp.envs.tasks.goal import GoalTask
from rlgrasp.train.loop import train
from rlgrasp.train.parts import build_parts
from rlgrasp.train.validate import validate_train
from tests.helpers import our_lines, run_entry
from tests.test_sac import SMALL

#: SAC on pick-and-place with the sparse reward and HER, read as one vector.
HER = ["task=pick_place", "env.task.observation=flat", "env.task.reward=sparse", "algo.her.enabled=true"]
#: Steps of an episode in the synthetic batches, and envs and steps a batch.
LENGTH, ENVS, STEPS = 10, 3, 4


def _sac(tmp_path: Path, *overrides: str) -> SAC:
    """A HER SAC whose buffer (200 rows) wraps, and that takes no gradient step on the toy batches."""
    cfg = compose_train(
        [
            *SMALL,
            *HER,
            f"paths.output_dir={tmp_path}",
            "algo.replay.buffer_frames=200",
            "algo.replay.learning_starts=200",
            "algo.optim.utd_ratio=0.0001",
            *overrides,
        ]
    )
    torch.manual_seed(0)
    return SAC(cfg, build_parts(cfg), torch.device("cpu"))


class Episodes:
    """Toy batches ``[envs, steps]`` whose observations say which episode, step and env they are:
    the object at ``(episode, step, env)`` (``(episode, step + 1, env)`` in the next observation), the
    desired goal at -1. Each env's episodes last ``LENGTH`` steps, its first one cut short by the env's
    number of steps (as staggered starts do), so episodes end at different steps in different envs."""

    def __init__(self, sac: SAC) -> None:
        self.dim = sac.parts.spec["obs_dim"]
        self.act = len(sac.parts.spec["action_low"])
        self.layout = sac.her.layout
        self.episode = list(range(ENVS))  # each env's episode number (unique: env + ENVS x k)
        self.step = [0] * ENVS
        self.length = [LENGTH - env for env in range(ENVS)]

    def length_of(self, episode: int) -> int:
        """An ended episode's steps (its first ones, numbered below ENVS, were cut short)."""
        return LENGTH - episode if episode < ENVS else LENGTH

    def batch(self) -> TensorDict:
        obs, nxt = torch.zeros(ENVS, STEPS, self.dim), torch.zeros(ENVS, STEPS, self.dim)
        obs[..., self.layout.desired] = -1.0
        nxt[..., self.layout.desired] = -1.0
        done = torch.zeros(ENVS, STEPS, 1, dtype=torch.bool)
        for env in range(ENVS):
            for t in range(STEPS):
                code = [self.episode[env], self.step[env], env]
                obs[env, t, self.layout.achieved] = torch.tensor(code, dtype=torch.float32)
                nxt[env, t, self.layout.achieved] = torch.tensor(
                    [code[0], code[1] + 1, env], dtype=torch.float32
                )
                self.step[env] += 1
                if self.step[env] == self.length[env]:
                    done[env, t] = True
                    self.episode[env] += ENVS
                    self.step[env], self.length[env] = 0, LENGTH
        reward = torch.zeros(ENVS, STEPS, 1)
        nexts = {"observation": nxt, "reward": reward, "done": done, "terminated": torch.zeros_like(done)}
        return TensorDict(
            {"observation": obs, "action": torch.zeros(ENVS, STEPS, self.act), "next": nexts}, [ENVS, STEPS]
        )


def _filled(sac: SAC, frames: int) -> Episodes:
    episodes = Episodes(sac)
    for _ in range(frames // (ENVS * STEPS)):
        sac.update(episodes.batch(), 0)
    return episodes


def _task_reward(achieved: torch.Tensor, desired: torch.Tensor, threshold: float) -> np.ndarray:
    """The task's own rule, ``GoalTask.compute_reward`` (numpy, vectorized)."""
    task = SimpleNamespace(distance_threshold=threshold)
    return GoalTask.compute_reward(task, achieved.numpy(), desired.numpy())


def test_a_relabelled_goal_is_a_later_achieved_goal_of_the_same_episode(tmp_path: Path) -> None:
    sac = _sac(tmp_path)
    _filled(sac, 600)  # the 200-row ring written three times over: episodes straddle its end
    layout, later = sac.her.layout, []
    for _ in range(20):
        sample = sac.replay.sample()
        relabelled, chosen = sac.her.relabel(sample)
        obs, nxt = relabelled["observation"][chosen], relabelled["next", "observation"][chosen]
        goal, own = obs[:, layout.desired], nxt[:, layout.achieved]  # own: (episode, step + 1, env)
        assert torch.equal(nxt[:, layout.desired], goal)
        assert torch.equal(goal[:, 0], own[:, 0]) and torch.equal(goal[:, 2], own[:, 2])  # its episode
        assert bool((goal[:, 1] >= own[:, 1]).all())  # at its step or later
        reward = relabelled["next", "reward"][chosen].squeeze(-1)
        assert np.array_equal(reward.numpy(), _task_reward(own, goal, layout.distance_threshold))
        later += (goal[:, 1] - own[:, 1]).tolist()
        kept = torch.ones(len(sample), dtype=torch.bool)
        kept[chosen] = False
        assert torch.equal(relabelled["observation"][kept], sample["observation"][kept])
    assert max(later) >= STEPS  # goals from a later batch than the row's own
    assert 0 in later  # SB3's "future" includes the row's own step (reward 1)


def test_final_takes_the_last_stored_step_of_the_episode(tmp_path: Path) -> None:
    sac = _sac(tmp_path, "algo.her.strategy=final", "algo.her.relabel_ratio=1")
    episodes = _filled(sac, 240)
    relabelled, _ = sac.her.relabel(sac.replay.sample())
    goal = relabelled["observation"][:, sac.her.layout.desired]
    for episode, step, env in goal.tolist():
        ended = int(episode) != episodes.episode[int(env)]  # else still running: its newest step
        assert int(step) == (episodes.length_of(int(episode)) if ended else episodes.step[int(env)])


def test_the_share_relabelled_is_the_ratio_and_demonstrations_are_not_in_it(tmp_path: Path) -> None:
    sac = _sac(tmp_path, "algo.her.relabel_ratio=0.25")
    _filled(sac, 240)
    desired = sac.her.layout.desired
    for _ in range(10):
        minibatch = sac._sample()
        unchanged = (minibatch["observation"][:, desired] == -1).all(-1)
        assert int(unchanged.sum()) == 32 - round(32 * 0.25)
        assert EPISODE_KEY not in minibatch.keys()  # the demonstrations' rows have no episode number


def test_the_sparse_rule_on_tensors_is_the_tasks_own() -> None:
    torch.manual_seed(0)
    layout = GoalLayout(slice(0, 3), slice(3, 6), 0.05)
    achieved, desired = torch.rand(4000, 3) * 0.1, torch.rand(4000, 3) * 0.1
    ours = layout.reward(achieved, desired).squeeze(-1).numpy()
    assert np.array_equal(ours, _task_reward(achieved, desired, 0.05)) and 0.05 < ours.mean() < 0.95


def test_a_resumed_run_relabels_the_transitions_it_reads_back(tmp_path: Path) -> None:
    sac = _sac(tmp_path)
    _filled(sac, 360)
    sac.save_extra(tmp_path)
    resumed = _sac(tmp_path)
    resumed.load_replay(tmp_path)
    episodes = _filled(resumed, 48)  # new episodes, numbered after those read back
    layout = resumed.her.layout
    for _ in range(10):
        relabelled, chosen = resumed.her.relabel(resumed.replay.sample())
        goal = relabelled["observation"][chosen][:, layout.desired]
        own = relabelled["next", "observation"][chosen][:, layout.achieved]
        assert torch.equal(goal[:, 0], own[:, 0]) and bool((goal[:, 1] >= own[:, 1]).all())
    assert len(resumed.replay) == 200 and episodes.episode[0] > 0


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (
            ["task=lift", "algo.her.enabled=true"],
            "algo.her.enabled=True: relabelled rewards are recomputed with a goal task's sparse rule",
        ),
        (
            [*HER, "env.task.reward=dense"],
            "needs a goal task (task=pick_place or task=push) with env.task.reward=sparse, not 'dense'",
        ),
        ([*HER, "algo.her.strategy=episode"], "algo.her.strategy='episode': must be future or final"),
        ([*HER, "algo.her.relabel_ratio=1.5"], "algo.her.relabel_ratio=1.5: must be in [0, 1]"),
        ([*HER, "cameras=wrist_depth", "model=cnn"], "algo.her.enabled=True: relabels the goal in a state"),
    ],
)
def test_what_her_cannot_serve_is_refused_in_one_line(
    tmp_path: Path, overrides: list[str], message: str
) -> None:
    with pytest.raises(ConfigError) as info:
        validate_train(compose_train([*SMALL, f"paths.output_dir={tmp_path}", *overrides]))
    assert message in str(info.value) and "\n" not in str(info.value)


def _one_error_line(tmp_path: Path, capsys: Any, args: list[str]) -> str:
    """scripts/train.py with ``args`` in this process: it fails with one error line and no traceback."""
    code = run_entry("train", ["logger=none", f"paths.root_dir={tmp_path}", *args], tmp_path)
    out = capsys.readouterr()
    errors = [ln for ln in our_lines(out.out + "\n" + out.err) if ln.startswith("error:") or "[ERROR]" in ln]
    assert code != 0 and "Traceback" not in out.out + out.err and len(errors) == 1, out
    return errors[0]


def test_ppo_has_no_her_key(tmp_path: Path, capsys: Any) -> None:
    line = _one_error_line(tmp_path, capsys, ["experiment=smoke", "algo.her.enabled=true"])
    assert "algo.her: unknown key 'her'; algo has _target_, name, loss, optim, schedule" in line


@pytest.mark.parametrize(
    ("task", "message"),
    [
        ("lift", "algo.her.enabled=true: the task LiftTask has no goal to relabel; HER needs a goal task"),
        ("stack", "algo.her.enabled=true: StackTask's success is not the goal distance alone"),
    ],
)
def test_a_task_her_cannot_relabel_is_refused_before_any_worker(
    tmp_path: Path, capsys: Any, task: str, message: str
) -> None:
    flat = ["env.task.observation=flat"] if task != "lift" else []  # lift has no goal to append
    args = ["experiment=grasp_sac", f"task={task}", "env.task.reward=sparse", "algo.her.enabled=true", *flat]
    assert message in _one_error_line(tmp_path, capsys, args)


def test_a_short_her_run_trains(tmp_path: Path) -> None:
    run = tmp_path / "run"
    success = train(compose_train([*SMALL, *HER, f"paths.output_dir={run}", "total_frames=192"]))
    last = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert 0.0 <= success <= 1.0 and last["updates"] > 0 and last["config"]["algo"]["her"]["enabled"]


def test_her_beside_demonstrations_samples_both(tmp_path: Path) -> None:
    """HER on the online rows and the expert's (sparse-reward) episodes beside them: the
    demonstrations carry no episode number and are never relabelled."""
    from rlgrasp.compose import compose_config
    from rlgrasp.demos.cli import record_demos

    out = tmp_path / "demos"
    demo_task = ["task=pick_place", "env.task.observation=flat", "env.task.reward=sparse"]
    record_demos(
        compose_config(
            "demos",
            ["episodes=1", f"out={out}", "workers=1", "keep=all", "env.control.ee_yaw=true", *demo_task],
        )
    )
    sac = _sac(tmp_path, f"algo.demos={out / 'demos'}", "env.control.ee_yaw=true")
    _filled(sac, 240)
    minibatch = sac._sample()
    assert EPISODE_KEY not in minibatch.keys() and minibatch.shape[0] == 32


def test_tqc_takes_her_as_sac_does(tmp_path: Path) -> None:
    from tests.test_tqc import _tqc

    tqc = _tqc(tmp_path, *HER, "algo.replay.learning_starts=24", "algo.optim.utd_ratio=0.1")
    episodes = Episodes(tqc)
    metrics = [tqc.update(episodes.batch(), 0) for _ in range(4)][-1]
    assert tqc.her is not None and metrics["charts/gradient_steps"] > 0 and "her/relabelled_reward" in metrics
