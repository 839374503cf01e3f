"""Modules that moved (``rlgrasp.legacy.MOVED_MODULES``): a checkpoint or run folder written before
names its parts by the old module path, and reads as today's class; nothing is left at the old path."""

from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path
from typing import Any

import pytest
import torch

from rlgrasp.legacy import MOVED_MODULES, moved_target
from rlgrasp.policy_file import read_checkpoint
from rlgrasp.received import PARTS, ReceivedError, read_config

ROOT = Path(__file__).resolve().parents[1]


def _old_parts() -> list[tuple[str, str, str, str]]:
    """``(kind, short name, old path, today's path)`` of each of rlgrasp's parts whose module moved."""
    found = []
    for old, new in MOVED_MODULES.items():
        for kind, parts in PARTS.items():
            for name, cls in parts.items():
                if cls.rpartition(".")[0] == new:
                    found.append((kind, name, f"{old}.{cls.rpartition('.')[2]}", cls))
    return found


def _naming(kind: str, target: str) -> dict[str, Any]:
    """A saved config naming ``target`` at the node where a part of ``kind`` is built."""
    if kind == "algo_term":
        return {"algo": {"_target_": PARTS["algo"]["ppo"], "terms": {"x": {"_target_": target}}}}
    return {kind: {"_target_": target}}


def _read_back(kind: str, read: dict[str, Any]) -> Any:
    if kind == "algo_term":
        return read["algo"]["terms"]["x"]["_target_"]
    return read[kind] if kind == "logger" else read[kind]["_target_"]


@pytest.mark.parametrize(("kind", "name", "old", "new"), _old_parts(), ids=lambda v: str(v))
def test_a_part_named_by_its_old_module_reads_as_todays_class(kind: str, name: str, old: str, new: str):
    read = read_config(_naming(kind, old), "old.pt")
    assert _read_back(kind, read) == ({"name": name} if kind == "logger" else new)
    assert moved_target(old) == new


def test_a_config_naming_the_old_modules_reads_as_todays_classes() -> None:
    old = {
        "collector": {"_target_": "rlgrasp.train.collectors.ProcessCollector", "num_workers": 2},
        "algo": {
            "_target_": "rlgrasp.algos.ppo.PPO",
            "terms": {"rnd": {"_target_": "rlgrasp.train.rnd.RND"}},
        },
        "logger": {"_target_": "rlgrasp.train.trackers.WandbLogger", "project": "p"},
    }
    read = read_config(old, "old.pt")
    assert read["collector"] == {
        "_target_": "rlgrasp.train.collection.collectors.ProcessCollector",
        "num_workers": 2,
    }
    assert read["algo"]["terms"]["rnd"]["_target_"] == "rlgrasp.algos.ppo.rnd.RND"
    assert read["logger"] == {"name": "wandb"}
    tensorboard = read_config({"logger": {"_target_": "rlgrasp.train.logger.TensorBoardLogger"}}, "old.pt")
    assert tensorboard["logger"] == {"name": "tensorboard"}


def test_a_shipped_policy_written_before_the_split_loads() -> None:
    path = ROOT / "policies" / "grasp_ppo_xarm6.pt"
    saved = torch.load(path, weights_only=True)["config"]
    assert saved["collector"]["_target_"] == "rlgrasp.train.collectors.ProcessCollector"  # as written then
    state = read_checkpoint(path)
    assert state["config"]["collector"]["_target_"] == PARTS["collector"]["process"]
    assert state["config"]["logger"] == {"name": "tensorboard"}


def test_a_moved_module_is_gone_from_its_old_path_and_imports_at_its_new_one() -> None:
    """The map is the one route for an old name: no re-export module is left behind."""
    for old, new in MOVED_MODULES.items():
        assert importlib.util.find_spec(old) is None, f"{old} is still importable"
        importlib.import_module(new)


def test_the_map_moves_only_modules_and_trusts_nothing_new() -> None:
    """An old path reads back only into a part of that node's kind: a moved class elsewhere, or a
    name in a moved module that is no part, is refused as before."""
    assert moved_target("rlgrasp.train.rnd") == "rlgrasp.train.rnd"  # a module alone is no class path
    assert moved_target("mypkg.train.rnd.RND") == "mypkg.train.rnd.RND"
    with pytest.raises(ReceivedError, match="is not a part rlgrasp builds at env"):
        read_config({"env": {"_target_": "rlgrasp.train.rnd.RND"}}, "old.pt")
    with pytest.raises(ReceivedError, match="is not a part rlgrasp builds"):
        read_config(_naming("algo_term", "rlgrasp.train.rnd.torch"), "old.pt")
