"""A file someone sends cannot act on this machine (``rlgrasp.received``): every reader refuses a
checkpoint whose config would make Hydra's ``instantiate`` call something of the sender's choosing,
in one line, before anything is built; a demonstrations folder holding anything but plain tensors is
refused before anything could unpickle it. Each test proves the target never ran: the file it would
have created does not exist afterwards. (The randomized version of these: tests/test_fuzz_received.py.)"""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import pytest
import torch

from rlgrasp.compose import compose_config, compose_train
from rlgrasp.config import ConfigError
from rlgrasp.demos.dataset import DemoError, load_demos
from rlgrasp.evaluation import EvaluationError
from rlgrasp.policy_file import CheckpointError
from rlgrasp.received import PARTS, ReceivedError, memmap_entries, read_config
from rlgrasp.train.loop import Trainer

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "policies" / "grasp_ppo.pt"


def _opener(victim: Path) -> dict:
    """What truncated a file of the sender's choosing before the allow-list existed."""
    return {"_target_": "builtins.open", "_args_": [str(victim), "w"]}


def crafted_policy(tmp_path: Path, victim: Path) -> Path:
    """The shipped policy with ``config.env.randomization`` replaced by a call to ``open``."""
    ckpt = torch.load(SHIPPED, weights_only=True)
    ckpt["config"]["env"]["randomization"] = _opener(victim)
    path = tmp_path / "crafted.pt"
    torch.save(ckpt, path)
    return path


def crafted_run(tmp_path: Path, victim: Path) -> Path:
    """A training run directory whose ``last.pt`` carries the same call (for resume)."""
    run = tmp_path / "run"
    trainer = Trainer(compose_train(["experiment=smoke", "logger=none", f"paths.output_dir={run}"]))
    trainer.save()
    trainer.logger.close()
    for ckpt_file in (run / "checkpoints").glob("*.pt"):
        ckpt = torch.load(ckpt_file, weights_only=True)
        ckpt["config"]["env"]["randomization"] = _opener(victim)
        torch.save(ckpt, ckpt_file)
    return run


def _refused(info: pytest.ExceptionInfo, victim: Path) -> None:
    message = str(info.value)
    assert "refused" in message and "config.env.randomization._target_" in message, message
    assert "\n" not in message
    assert not victim.exists()  # the target was never called


def test_evaluation_refuses_and_calls_nothing(tmp_path: Path) -> None:
    from rlgrasp.evaluation.cli import evaluate

    victim = tmp_path / "pwned"
    cfg = compose_config(
        "eval",
        [
            f"ckpt={crafted_policy(tmp_path, victim)}",
            "episodes=1",
            "video=false",
            f"out_dir={tmp_path / 'eval'}",
        ],
    )
    with pytest.raises(EvaluationError) as info:
        evaluate(cfg)
    _refused(info, victim)


def test_export_refuses_and_calls_nothing(tmp_path: Path) -> None:
    from rlgrasp.export import ExportError, export, register_export_config

    victim = tmp_path / "pwned"
    register_export_config()
    cfg = compose_config("export", [f"ckpt={crafted_policy(tmp_path, victim)}", f"out={tmp_path / 'p.pt'}"])
    with pytest.raises(ExportError) as info:
        export(cfg)
    _refused(info, victim)
    assert not (tmp_path / "p.pt").exists()


def test_enjoy_refuses_and_calls_nothing(tmp_path: Path) -> None:
    from rlgrasp.evaluation.enjoy import check, register_enjoy_config

    victim = tmp_path / "pwned"
    register_enjoy_config()
    with pytest.raises(EvaluationError) as info:
        check(compose_config("enjoy", [f"ckpt={crafted_policy(tmp_path, victim)}"]))
    _refused(info, victim)


def test_resume_refuses_and_calls_nothing(tmp_path: Path) -> None:
    from rlgrasp.train.resume import prepare_run

    victim = tmp_path / "pwned"
    run = crafted_run(tmp_path, victim)
    with pytest.raises(CheckpointError) as info:
        prepare_run(
            compose_train(["experiment=smoke", "logger=none", f"paths.output_dir={run}", f"resume={run}"])
        )
    assert "refused" in str(info.value) and not victim.exists()


def test_a_teacher_and_a_warm_start_refuse_and_call_nothing(tmp_path: Path) -> None:
    from rlgrasp.train.warm_start import warm_start
    from rlgrasp.vision.dagger import load_teacher

    victim = tmp_path / "pwned"
    path = crafted_policy(tmp_path, victim)
    with pytest.raises(CheckpointError) as info:
        load_teacher(str(path), {}, {})
    _refused(info, victim)
    cfg = compose_train(["experiment=smoke", "logger=none", f"paths.output_dir={tmp_path / 'r'}"])
    with pytest.raises((CheckpointError, ConfigError)) as info:
        warm_start(torch.nn.Linear(1, 1), str(path), cfg.env, cfg.model)
    _refused(info, victim)


def test_recording_demonstrations_with_a_received_policy_refuses(tmp_path: Path) -> None:
    from rlgrasp.demos.cli import DemosInputError, record_demos

    victim = tmp_path / "pwned"
    cfg = compose_config(
        "demos",
        ["episodes=1", f"out={tmp_path / 'd'}", "workers=1", f"policy={crafted_policy(tmp_path, victim)}"],
    )
    with pytest.raises(DemosInputError) as info:
        record_demos(cfg)
    _refused(info, victim)


def test_the_adr_report_refuses_and_calls_nothing(tmp_path: Path, capsys) -> None:
    spec = importlib.util.spec_from_file_location("adr_report", ROOT / "scripts" / "adr_report.py")
    adr_report = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(adr_report)
    victim = tmp_path / "pwned"
    assert adr_report.main([str(crafted_policy(tmp_path, victim)), "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "refused" in err and "\n" not in err
    assert not victim.exists()


def test_demonstrations_holding_anything_but_plain_tensors_are_refused(tmp_path: Path) -> None:
    from rlgrasp.demos.cli import record_demos

    out = tmp_path / "cube"
    record_demos(compose_config("demos", ["episodes=1", f"out={out}", "workers=1", "keep=all"]))
    frames = out / "demos" / "frames"
    memmap_entries(frames, "demos")  # what rlgrasp-demos writes passes
    layout = _layout()
    (frames / "other.pickle").write_bytes(b"\x80\x04N.")
    with pytest.raises(DemoError, match="other.pickle in .* is not a tensor file"):
        load_demos(out / "demos", layout)
    (frames / "other.pickle").unlink()
    meta = json.loads((frames / "meta.json").read_text())
    meta["_type"] = "<class 'tensordict.tensorclass.NonTensorData'>"
    (frames / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(DemoError, match="not plain tensors"):
        load_demos(out / "demos", layout)
    shutil.rmtree(frames)


def _layout() -> dict:
    from rlgrasp.demos.dataset import layout_of
    from rlgrasp.envs.factory import env_factory

    cfg = compose_train(["env.control.mode=ee_delta", "paths.output_dir=."])
    env = env_factory(cfg.env)()
    try:
        return layout_of(env, dict(cfg.env))
    finally:
        env.close()


@pytest.mark.parametrize(
    ("config", "where"),
    [
        (
            {"env": {"_target_": "builtins.open"}},
            "config.env._target_='builtins.open' is not a part rlgrasp builds at env",
        ),
        (
            {"env": {"_target_": "rlgrasp.envs.PandaGraspEnv", "robot": [{"x": {"_target_": "os.getcwd"}}]}},
            "config.env.robot[0].x._target_ would be called",
        ),
        (
            {"env": {"_target_": "rlgrasp.envs.PandaGraspEnv", "_args_": ["x"]}},
            "config.env._args_ would be called",
        ),
        ({"collector": {"_target_": "shutil.copyfile"}}, "config.collector._target_='shutil.copyfile'"),
        (
            {"algo": {"_target_": "rlgrasp.algos.sac.SAC", "demos": {"_partial_": True}}},
            "config.algo.demos._partial_ would be called",
        ),
        (
            {"algo": {"_target_": "rlgrasp.algos.ppo.PPO", "terms": {"x": {"_target_": "builtins.open"}}}},
            "config.algo.terms.x._target_='builtins.open' is not a part rlgrasp builds",
        ),
        (
            {
                "algo": {
                    "terms": {
                        "rnd": {"_target_": "rlgrasp.algos.ppo.rnd.RND", "net": {"_target_": "os.getcwd"}}
                    }
                }
            },
            "config.algo.terms.rnd.net._target_ would be called",
        ),
        (
            {"env": {"_target_": "rlgrasp.envs.PandaGraspEnv", "objects": "${oc.env:HOME}"}},
            "config.env.objects holds an interpolation",
        ),
        (  # an older format is upgraded into a short name, never into a target (route 1 of #81)
            {"env": {"gym_factory": "builtins:open", "kwargs": {"file": "x", "mode": "w"}}},
            "config.env.gym_factory='builtins:open' is not an env rlgrasp builds",
        ),
        (
            {"collector": {"backend": "shutil.copyfile"}},
            "config.collector.backend='shutil.copyfile' is not a collector rlgrasp builds",
        ),
        (  # the trust is per kind: one of rlgrasp's loggers is nothing at env (route 4)
            {
                "env": {
                    "_target_": "rlgrasp.train.tracking.trackers.MlflowLogger",
                    "tracking_uri": "file:///x",
                }
            },
            "config.env._target_='rlgrasp.train.tracking.trackers.MlflowLogger' is not a part rlgrasp builds "
            "at env",
        ),
        (  # a dotted top-level key (route 8)
            {"algo.terms.x": {"_target_": "builtins.open"}},
            "config has the key 'algo.terms.x'; a saved config nests its keys",
        ),
        ({"env": "grasp"}, "config.env is a str, not a mapping"),
    ],
)
def test_a_received_config_names_the_key_and_the_target(config: dict, where: str) -> None:
    with pytest.raises(ReceivedError) as info:
        read_config(config, "f.pt")
    assert where in str(info.value) and "\n" not in str(info.value)


def test_a_files_logger_is_only_named_and_never_built() -> None:
    """Route 3 of #81: an MLflow tracking URI of the file's choosing; the node keeps only a name."""
    endpoint = {
        "_target_": "rlgrasp.train.tracking.trackers.MlflowLogger",
        "tracking_uri": "http://203.0.113.1:5000",
    }
    assert read_config({"logger": endpoint}, "f.pt")["logger"] == {"name": "mlflow"}
    assert read_config({"logger": {"_target_": "os.remove", "path": "/x"}}, "f.pt")["logger"] == {
        "name": "another"
    }


def test_rlgrasp_parts_and_a_users_own_class_from_their_own_config_pass() -> None:
    shipped = read_config(torch.load(SHIPPED, weights_only=True)["config"], "shipped")
    assert shipped["env"]["_target_"] == PARTS["env"]["grasp"]
    mine = {"collector": {"_target_": "mypkg.MyCollector"}}
    with pytest.raises(ReceivedError):
        read_config(mine, "f.pt")
    assert read_config(mine, "f.pt", user=mine)["collector"]["_target_"] == "mypkg.MyCollector"
    # an algorithm's terms: rlgrasp's own classes pass, a user's own when their own config names it there
    terms = {"imitation": {"_target_": "rlgrasp.demos.bc.Imitation"}, "mine": {"_target_": "mypkg.Term"}}
    with pytest.raises(ReceivedError, match="config.algo.terms.mine._target_='mypkg.Term'"):
        read_config({"algo": {"terms": terms}}, "f.pt")
    read_config({"algo": {"terms": terms}}, "f.pt", user={"algo": {"terms": terms}})
    # the trust is per node: the user's class at algo.terms.mine is nothing at env, nor at another term
    with pytest.raises(ReceivedError, match="config.env._target_='mypkg.Term'"):
        read_config({"env": {"_target_": "mypkg.Term"}}, "f.pt", user={"algo": {"terms": terms}})
    with pytest.raises(ReceivedError, match="config.algo.terms.other._target_='mypkg.Term'"):
        read_config({"algo": {"terms": {"other": terms["mine"]}}}, "f.pt", user={"algo": {"terms": terms}})


def test_a_checkpoint_of_a_newer_format_is_refused_by_every_loader(tmp_path: Path) -> None:
    from rlgrasp.evaluation.source import load_checked_checkpoint
    from rlgrasp.policy_file import read_checkpoint

    ckpt = torch.load(SHIPPED, weights_only=True)
    ckpt["format"] = 99
    torch.save(ckpt, tmp_path / "future.pt")
    with pytest.raises(CheckpointError, match="has format 99, this version reads up to format 2"):
        read_checkpoint(tmp_path / "future.pt")
    with pytest.raises(EvaluationError, match="has format 99, this version reads up to format 2"):
        load_checked_checkpoint(tmp_path / "future.pt")


def test_reading_a_read_config_keeps_its_logger_record() -> None:
    """A policy-only file keeps the config as read (its logger a record, ``{"name": ...}``); read again,
    the record stays what it was, and a name that is not rlgrasp's is recorded as "another"."""
    from rlgrasp.received import read_config

    once = read_config({"logger": {"_target_": "rlgrasp.train.tracking.logger.TensorBoardLogger"}}, "test")
    assert once["logger"] == {"name": "tensorboard"}
    assert read_config(once, "test")["logger"] == {"name": "tensorboard"}
    assert read_config({"logger": {"name": "os.system"}}, "test")["logger"] == {"name": "another"}
