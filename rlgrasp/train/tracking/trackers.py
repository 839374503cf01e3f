"""Team experiment tracking besides TensorBoard: Weights & Biases (``logger=wandb``,
``WandbLogger``) or MLflow (``logger=mlflow``, ``MlflowLogger``), optional extras.

TensorBoard stays on; the ``Tracker`` receives the same ``scalars`` / ``text`` / ``hparams`` calls
(same tags, x = env frames) plus the resolved config at start. The tracker's run id is stored in
``<run dir>/tracker.json``, so ``resume=<run dir>`` continues the same W&B or MLflow run. The
libraries are used directly rather than through TorchRL's loggers, for that resume by id.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import math
import os
import socket
import time
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from rlgrasp.errors import ConfigError
from rlgrasp.train.tracking.logger import TensorBoardLogger
from rlgrasp.utils import flatten

log = logging.getLogger("rlgrasp.train")
ID_FILE = "tracker.json"


#: How long a tracking server may take to accept a connection before the run is refused.
CONNECT_TIMEOUT_S = 5.0


def unreachable(
    uri: str | None, key: str = "logger.tracking_uri", timeout_s: float = CONNECT_TIMEOUT_S
) -> str | None:
    """Why the server of an ``http(s)://`` tracking URI cannot be reached (``None``: it accepts a
    connection, or the URI is a folder or database). Asked once, with a bounded wait: MLflow's own
    client retries a refused connection with back-off for minutes, then fails with a traceback."""
    parsed = urlsplit(uri or "")
    if parsed.scheme not in ("http", "https"):
        return None
    try:
        port = parsed.port or (443 if parsed.scheme == "https" else 80)
        with socket.create_connection((parsed.hostname or "", port), timeout=timeout_s):
            return None
    except ValueError as exc:  # a port that is not a number
        return f"{key}={uri}: not a valid URI ({exc})"
    except OSError as exc:
        reason = "no answer" if isinstance(exc, TimeoutError) else (exc.strerror or type(exc).__name__)
        return (
            f"{key}={uri}: no tracking server answers ({reason}; waited up to {timeout_s:g} s); "
            "start it, or log to a folder (logger.tracking_uri=file:<dir>)"
        )


class Tracker:
    """One tracker run: ``scalars``, ``text``, ``hparams``, ``close`` (the logger's calls)."""

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


class WandbTracker(Tracker):
    """A W&B run whose id lives in the run directory; x axis = the ``frames`` metric, so a resumed
    run's steps may go back to the checkpoint's frames without W&B dropping them."""

    def __init__(
        self, logger: WandbLogger, name: str, run_dir: Path, config: dict[str, Any], ids: dict[str, Any]
    ) -> None:
        import wandb  # an optional extra: imported only when logger=wandb

        self.run = wandb.init(
            project=logger.project,
            entity=logger.entity,
            mode=logger.mode,
            dir=str(run_dir),
            id=ids.get("id") or uuid.uuid4().hex[:12],
            resume="allow",
            name=name,
            tags=list(logger.tags),
            config=config,
            allow_val_change=True,  # a resume may change keys such as `resume` itself
        )
        self.run.define_metric("frames")
        self.run.define_metric("*", step_metric="frames")
        self.id = {"id": self.run.id, "project": logger.project}

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

    def __init__(
        self, logger: MlflowLogger, name: str, run_dir: Path, config: dict[str, Any], ids: dict[str, Any]
    ) -> None:
        from mlflow.tracking import MlflowClient  # an optional extra: imported only when logger=mlflow

        uri = logger.tracking_uri or os.environ.get("MLFLOW_TRACKING_URI") or "outputs/mlruns"
        if "://" not in uri or uri.startswith("file:"):
            # MLflow 3 asks for an explicit opt-in to its folder store; a folder needs no server.
            os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
        self.client = client = MlflowClient(tracking_uri=uri)
        run_id = ids.get("run_id")
        if run_id is None:
            exp = client.get_experiment_by_name(logger.project)
            exp_id = exp.experiment_id if exp else client.create_experiment(logger.project)
            tags = {t: "" for t in logger.tags} | {"rlgrasp.run_dir": str(run_dir)}
            run_id = client.create_run(exp_id, run_name=name, tags=tags).info.run_id
        else:
            client.update_run(run_id, status="RUNNING")
        self.run_id = run_id
        # Params cannot change once logged: on resume, log only keys the run does not have yet.
        have = client.get_run(run_id).data.params
        params = {k: str(v)[:6000] for k, v in flatten(config, leaf=lambda v: not v).items() if k not in have}
        if params:
            from mlflow.entities import Param  # optional extra, as above

            client.log_batch(run_id, params=[Param(k, v) for k, v in params.items()])
        self.id = {"run_id": run_id, "tracking_uri": uri, "experiment": logger.project}

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


class TrackedLogger(TensorBoardLogger):
    """TensorBoard and a ``Tracker`` fed the same calls; a resumed run continues the tracker run
    recorded in ``<run dir>/tracker.json``. ``kind``: the tracker's extra and its key in that file."""

    kind = ""

    def __init__(
        self,
        run_dir: Path,
        config: dict[str, Any],
        resumed_frames: int | None,
        console_interval_s: float,
        project: str,
        tags: Sequence[str],
        run_name: str | None,
    ) -> None:
        if importlib.util.find_spec(self.kind) is None:
            raise ConfigError(f'logger={self.kind} needs its extra: pip install -e ".[{self.kind}]"')
        super().__init__(run_dir, config, resumed_frames, console_interval_s)
        self.project, self.tags = project, list(tags)
        id_file = Path(run_dir) / ID_FILE
        resumed = resumed_frames is not None and id_file.is_file()
        stored = json.loads(id_file.read_text()).get(self.kind, {}) if resumed else {}
        name = run_name or f"{config.get('experiment_name', 'run')}/{Path(run_dir).name}"
        self.tracker = self.open_tracker(name, Path(run_dir), config, stored)
        id_file.write_text(json.dumps({self.kind: self.tracker.id}, indent=2) + "\n")
        log.info("tracking with %s: %s%s", self.kind, self.tracker.id, " (resumed)" if stored else "")

    def open_tracker(self, name: str, run_dir: Path, config: dict[str, Any], ids: dict[str, Any]) -> Tracker:
        """The tracker's run, continuing the one ``ids`` (from ``tracker.json``) name if any."""
        raise NotImplementedError

    def scalars(self, metrics: dict[str, float], step: int) -> None:
        super().scalars(metrics, step)
        self.tracker.scalars(metrics, step)

    def text(self, tag: str, text: str, step: int = 0) -> None:
        super().text(tag, text, step)
        self.tracker.text(tag, text, step)

    def hparams(self, hparams: dict[str, Any], metrics: dict[str, float]) -> None:
        super().hparams(hparams, metrics)
        self.tracker.hparams(hparams, metrics)

    def close(self) -> None:
        super().close()
        self.tracker.close()


class WandbLogger(TrackedLogger):
    """``logger=wandb``: TensorBoard plus a W&B run (keys: ``rlgrasp.logger_schema.WandbLoggerConfig``)."""

    kind = "wandb"

    def __init__(
        self,
        run_dir: Path,
        config: dict[str, Any],
        resumed_frames: int | None,
        console_interval_s: float = 5.0,
        project: str = "rlgrasp",
        tags: Sequence[str] = (),
        run_name: str | None = None,
        entity: str | None = None,
        mode: str | None = None,
    ) -> None:
        self.entity, self.mode = entity, mode
        super().__init__(run_dir, config, resumed_frames, console_interval_s, project, tags, run_name)

    def open_tracker(self, name: str, run_dir: Path, config: dict[str, Any], ids: dict[str, Any]) -> Tracker:
        return WandbTracker(self, name, run_dir, config, ids)


class MlflowLogger(TrackedLogger):
    """``logger=mlflow``: TensorBoard plus an MLflow run (its keys:
    ``rlgrasp.logger_schema.MlflowLoggerConfig``)."""

    kind = "mlflow"

    def __init__(
        self,
        run_dir: Path,
        config: dict[str, Any],
        resumed_frames: int | None,
        console_interval_s: float = 5.0,
        project: str = "rlgrasp",
        tags: Sequence[str] = (),
        run_name: str | None = None,
        tracking_uri: str | None = None,
    ) -> None:
        self.tracking_uri = tracking_uri
        problem = (
            unreachable(tracking_uri)
            if tracking_uri
            else unreachable(os.environ.get("MLFLOW_TRACKING_URI"), "$MLFLOW_TRACKING_URI")
        )
        if problem:  # before TensorBoard's folder: a refused start leaves nothing in the run directory
            raise ConfigError(problem)
        super().__init__(run_dir, config, resumed_frames, console_interval_s, project, tags, run_name)

    def open_tracker(self, name: str, run_dir: Path, config: dict[str, Any], ids: dict[str, Any]) -> Tracker:
        return MlflowTracker(self, name, run_dir, config, ids)
