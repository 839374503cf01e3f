"""Team experiment tracking besides TensorBoard: Weights & Biases (``logger=wandb``) or MLflow
(``logger=mlflow``), optional extras.

TensorBoard stays on; a ``Tracker`` receives the same ``scalars`` / ``text`` / ``hparams`` calls as
``RunLogger`` (same tags, x = env frames) plus the resolved config at start. The tracker's run id is
stored in ``<run dir>/tracker.json``, so ``resume=<run dir>`` continues the same W&B or MLflow run.
The libraries are used directly rather than through TorchRL's loggers, for that resume by id.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
import uuid
from pathlib import Path
from typing import Any

log = logging.getLogger("rlgrasp.train")
TRACKERS = ("wandb", "mlflow")
ID_FILE = "tracker.json"


class Tracker:
    """One tracker run: ``scalars``, ``text``, ``hparams``, ``close`` (the ``RunLogger`` calls)."""

    def scalars(self, metrics: dict[str, float], step: int) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def text(self, tag: str, text: str, step: int = 0) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def hparams(self, hparams: dict[str, Any], metrics: dict[str, float]) -> None:  # pragma: no cover
        raise NotImplementedError

    def close(self) -> None:  # pragma: no cover - interface
        raise NotImplementedError


def _finite(metrics: dict[str, float]) -> dict[str, float]:
    return {
        k: float(v)
        for k, v in metrics.items()
        if v is not None and not (isinstance(v, float) and not math.isfinite(v))
    }


def _flat(config: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in config.items():
        if isinstance(v, dict) and v:
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


class WandbTracker(Tracker):
    """A W&B run whose id lives in the run directory; x axis = the ``frames`` metric, so a resumed
    run's steps may go back to the checkpoint's frames without W&B dropping them."""

    def __init__(self, cfg: Any, name: str, run_dir: Path, config: dict[str, Any], run_id: str | None):
        import wandb  # an optional extra: imported only when logger=wandb

        self.run = wandb.init(
            project=cfg.project,
            entity=cfg.entity,
            mode=cfg.mode,
            dir=str(run_dir),
            id=run_id or uuid.uuid4().hex[:12],
            resume="allow",
            name=name,
            tags=list(cfg.tags),
            config=config,
            allow_val_change=True,  # a resume may change keys such as `resume` itself
        )
        self.run.define_metric("frames")
        self.run.define_metric("*", step_metric="frames")
        self.id = {"wandb": {"id": self.run.id, "project": cfg.project}}

    def scalars(self, metrics: dict[str, float], step: int) -> None:
        self.run.log({"frames": step, **_finite(metrics)})

    def text(self, tag: str, text: str, step: int = 0) -> None:
        self.run.summary[tag] = text

    def hparams(self, hparams: dict[str, Any], metrics: dict[str, float]) -> None:
        self.run.summary.update(_finite(metrics))  # the config is the run's config already

    def close(self) -> None:
        self.run.finish()


class MlflowTracker(Tracker):
    """An MLflow run (client API: no process-global active run, so sweeps in one process are safe)."""

    def __init__(self, cfg: Any, name: str, run_dir: Path, config: dict[str, Any], run_id: str | None):
        from mlflow.tracking import MlflowClient  # an optional extra: imported only when logger=mlflow

        uri = cfg.tracking_uri or os.environ.get("MLFLOW_TRACKING_URI") or "outputs/mlruns"
        if "://" not in uri or uri.startswith("file:"):
            # MLflow 3 asks for an explicit opt-in to its folder store; a folder needs no server.
            os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
        self.client = client = MlflowClient(tracking_uri=uri)
        if run_id is None:
            exp = client.get_experiment_by_name(cfg.project)
            exp_id = exp.experiment_id if exp else client.create_experiment(cfg.project)
            tags = {t: "" for t in cfg.tags} | {"rlgrasp.run_dir": str(run_dir)}
            run_id = client.create_run(exp_id, run_name=name, tags=tags).info.run_id
        else:
            client.update_run(run_id, status="RUNNING")
        self.run_id = run_id
        # Params cannot change once logged: on resume, log only keys the run does not have yet.
        have = client.get_run(run_id).data.params
        params = {k: str(v)[:6000] for k, v in _flat(config).items() if k not in have}
        if params:
            from mlflow.entities import Param  # optional extra, as above

            client.log_batch(run_id, params=[Param(k, v) for k, v in params.items()])
        self.id = {"mlflow": {"run_id": run_id, "tracking_uri": uri, "experiment": cfg.project}}

    def scalars(self, metrics: dict[str, float], step: int) -> None:
        from mlflow.entities import Metric  # optional extra, as above

        now = int(time.time() * 1000)
        batch = [Metric(k, v, now, step) for k, v in _finite(metrics).items()]
        if batch:
            self.client.log_batch(self.run_id, metrics=batch)

    def text(self, tag: str, text: str, step: int = 0) -> None:
        self.client.log_text(self.run_id, text, f"{tag}.yaml" if tag == "config" else f"{tag}.txt")

    def hparams(self, hparams: dict[str, Any], metrics: dict[str, float]) -> None:
        self.scalars(metrics, 0)  # the params went in at start

    def close(self) -> None:
        self.client.set_terminated(self.run_id)


class TrackedLogger:
    """A ``RunLogger`` (TensorBoard) and a ``Tracker`` fed the same calls."""

    def __init__(self, base: Any, tracker: Tracker) -> None:
        self.base, self.tracker = base, tracker

    def scalars(self, metrics: dict[str, float], step: int) -> None:
        self.base.scalars(metrics, step)
        self.tracker.scalars(metrics, step)

    def text(self, tag: str, text: str, step: int = 0) -> None:
        self.base.text(tag, text, step)
        self.tracker.text(tag, text, step)

    def hparams(self, hparams: dict[str, Any], metrics: dict[str, float]) -> None:
        self.base.hparams(hparams, metrics)
        self.tracker.hparams(hparams, metrics)

    def flush(self) -> None:
        self.base.flush()

    def close(self) -> None:
        self.base.close()
        self.tracker.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.base, name)


def attach_tracker(base: Any, logger_cfg: Any, run_dir: Path, config: dict[str, Any], resumed: bool) -> Any:
    """``base`` itself without a tracker configured, else a ``TrackedLogger``; a resumed run continues
    the tracker run recorded in ``<run dir>/tracker.json``."""
    kind = getattr(logger_cfg, "tracker", None)
    if not kind or kind == "none":
        return base
    if kind not in TRACKERS:
        raise ValueError(f"logger.tracker must be one of {', '.join(TRACKERS)}, got {kind!r}")
    id_file = Path(run_dir) / ID_FILE
    stored = json.loads(id_file.read_text()) if resumed and id_file.is_file() else {}
    try:
        __import__(kind)
    except ImportError as exc:
        raise ImportError(f'logger={kind} needs its extra: pip install -e ".[{kind}]"') from exc
    name = logger_cfg.run_name or f"{config.get('experiment_name', 'run')}/{Path(run_dir).name}"
    if kind == "wandb":
        run_id = stored.get("wandb", {}).get("id")
        tracker: Tracker = WandbTracker(logger_cfg, name, Path(run_dir), config, run_id)
    else:
        run_id = stored.get("mlflow", {}).get("run_id")
        tracker = MlflowTracker(logger_cfg, name, Path(run_dir), config, run_id)
    id_file.write_text(json.dumps(tracker.id, indent=2) + "\n")
    log.info("tracking with %s: %s%s", kind, tracker.id[kind], " (resumed)" if stored else "")
    return TrackedLogger(base, tracker)
