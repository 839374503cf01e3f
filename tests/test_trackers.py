"""logger=wandb / logger=mlflow, offline: the TensorBoard tags, the config and the user's tags reach the
tracker, and ``resume=`` continues the same tracker run. Short in-process runs on a stand-in env."""

from __future__ import annotations

import importlib.util
import json
import time
from pathlib import Path
from typing import Any

import pytest

from rlgrasp.config import ConfigError
from rlgrasp.train.loop import train

STAND_IN = {"_target_": "tests.standins.pendulum", "max_episode_steps": 20}
TAGS = ("charts/SPS", "losses/policy_loss", "losses/value_loss", "eval/mean_reward", "time/collect_s")


@pytest.fixture(autouse=True)
def _offline(monkeypatch: pytest.MonkeyPatch) -> None:
    """Nothing may leave the machine: W&B offline, MLflow without telemetry."""
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.setenv("MLFLOW_DISABLE_TELEMETRY", "true")
    monkeypatch.setenv("DO_NOT_TRACK", "1")


def _train(train_cfg, run_dir: Path, frames: int, *overrides: str) -> None:
    resume = [f"resume={run_dir}"] if (run_dir / "checkpoints").is_dir() else []
    cfg = train_cfg(
        "experiment=smoke",
        "collector=single",
        f"total_frames={frames}",
        "eval.final_episodes=4",
        *overrides,
        *resume,
        run_dir=run_dir,
    )
    cfg.env = STAND_IN
    train(cfg)


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_mlflow_gets_tags_config_and_resumes_the_same_run(tmp_path: Path, train_cfg) -> None:
    pytest.importorskip("mlflow")
    from mlflow.tracking import MlflowClient  # an optional extra: skipped above without it

    run_dir, store = tmp_path / "run", tmp_path / "mlruns"
    over = (
        "logger=mlflow",
        f"logger.tracking_uri=file://{store}",
        "logger.project=unit",
        "logger.tags=[panda,smoke]",
    )
    _train(train_cfg, run_dir, 1024, *over)
    run_id = json.loads((run_dir / "tracker.json").read_text())["mlflow"]["run_id"]
    _train(train_cfg, run_dir, 2048, *over)
    assert json.loads((run_dir / "tracker.json").read_text())["mlflow"]["run_id"] == run_id

    client = MlflowClient(tracking_uri=f"file://{store}")
    runs = client.search_runs([client.get_experiment_by_name("unit").experiment_id])
    assert [r.info.run_id for r in runs] == [run_id]  # one run, continued
    data = runs[0].data
    assert set(TAGS) <= set(data.metrics)
    steps = [m.step for m in client.get_metric_history(run_id, "losses/policy_loss")]
    assert 1024 in steps and 2048 in steps
    assert data.params["algo.optim.lr"] == "0.0003" and data.params["experiment_name"] == "smoke"
    assert {"panda", "smoke"} <= set(data.tags) and data.tags["mlflow.runName"].startswith("smoke/")
    config = Path(client.download_artifacts(run_id, "config.yaml", str(tmp_path)))
    assert "gae_lambda" in config.read_text()


def _wandb_records(path: Path) -> list[Any]:
    """The records of a W&B transaction log (``run-<id>.wandb``): a 7-byte file header, then 32 kB
    blocks of chunks, each with a 7-byte header (crc32, little-endian length, type 1 full .. 4 last)."""
    from wandb.proto import wandb_internal_pb2 as pb  # an optional extra: only its test reads it

    data, pos, buf, out = path.read_bytes(), 7, b"", []
    while pos + 7 <= len(data):
        left = 32768 - pos % 32768
        length, kind = int.from_bytes(data[pos + 4 : pos + 6], "little"), data[pos + 6]
        if left < 7 or kind == 0:  # block trailer or zero padding
            pos += left
            continue
        buf += data[pos + 7 : pos + 7 + length]
        pos += 7 + length
        if kind in (1, 4):
            record = pb.Record()
            record.ParseFromString(buf)
            out.append(record)
            buf = b""
    return out


def _complete_records(logs: list[Path], timeout_s: float = 30.0) -> list[Any]:
    """The records of every log once each holds its exit record: W&B's service process writes the
    log on its own after ``finish()`` returns."""
    deadline = time.monotonic() + timeout_s
    while True:
        per_log = [_wandb_records(p) for p in logs]
        done = all(any(r.WhichOneof("record_type") == "exit" for r in recs) for recs in per_log)
        if done or time.monotonic() > deadline:
            return [r for recs in per_log for r in recs]
        time.sleep(0.2)


def _item(item: Any) -> tuple[str, Any]:
    """A history item's key and value (newer W&B writes keys as nested parts, values typed)."""
    key = item.key or "/".join(item.nested_key)
    kind = item.WhichOneof("value") if item.DESCRIPTOR.oneofs else None
    value = getattr(item, kind) if kind else json.loads(item.value_json or "null")
    return key, value


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_wandb_offline_gets_tags_config_and_resumes_the_same_run(tmp_path: Path, train_cfg) -> None:
    pytest.importorskip("wandb")
    run_dir = tmp_path / "run"
    over = ("logger=wandb", "logger.project=unit", "logger.tags=[panda,smoke]")
    _train(train_cfg, run_dir, 1024, *over)
    run_id = json.loads((run_dir / "tracker.json").read_text())["wandb"]["id"]
    _train(train_cfg, run_dir, 2048, *over)
    assert json.loads((run_dir / "tracker.json").read_text())["wandb"]["id"] == run_id

    logs = sorted(run_dir.glob("wandb/offline-run-*/run-*.wandb"))
    assert len(logs) == 2 and all(p.name == f"run-{run_id}.wandb" for p in logs)  # `wandb sync` joins them
    records = _complete_records(logs)
    runs = [r.run for r in records if r.WhichOneof("record_type") == "run"]
    assert runs and all(r.run_id == run_id for r in runs)
    assert {"panda", "smoke"} <= set(runs[0].tags) and runs[0].display_name.startswith("smoke/")
    config = {i.key: json.loads(i.value_json) for r in runs for i in r.config.update}
    config |= {
        i.key: json.loads(i.value_json)
        for r in records
        if r.WhichOneof("record_type") == "config"
        for i in r.config.update
    }
    assert config["algo"]["optim"]["lr"] == 3e-4 and config["experiment_name"] == "smoke"
    history = [
        dict(_item(i) for i in r.history.item) for r in records if r.WhichOneof("record_type") == "history"
    ]
    assert set(TAGS) <= {k for h in history for k in h}
    frames = {int(h["frames"]) for h in history if "losses/policy_loss" in h}
    assert {1024, 2048} <= frames


def test_a_tracker_without_its_extra_is_refused_in_one_line(
    tmp_path: Path, train_cfg, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Before any worker starts, and naming the extra to install."""
    find_spec = importlib.util.find_spec
    hidden = lambda name, *args: None if name == "wandb" else find_spec(name, *args)  # noqa: E731
    monkeypatch.setattr(importlib.util, "find_spec", hidden)
    with pytest.raises(ConfigError, match=r'logger=wandb needs its extra: pip install -e "\.\[wandb\]"'):
        _train(train_cfg, tmp_path / "run", 1024, "logger=wandb")
    assert not (tmp_path / "run" / "tracker.json").exists()
