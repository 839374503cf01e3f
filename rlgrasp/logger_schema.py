"""The logger part's schema (``logger=tensorboard|none|wandb|mlflow``): data only, at the bottom of the
package so that the run's config (``rlgrasp.config``) registers it without importing the training
core; the classes it names are ``rlgrasp.train.tracking.logger``'s and
``rlgrasp.train.tracking.trackers``'."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class LoggerConfig:
    """Where the run's curves go: ``_target_`` is a class of ``rlgrasp.train.tracking.logger`` (``logger=
    tensorboard``; ``none``: the console only) or ``rlgrasp.train.tracking.trackers`` (``wandb``, ``mlflow``:
    TensorBoard plus the tracker), built from the other keys."""

    _target_: str = "rlgrasp.train.tracking.logger.TensorBoardLogger"
    console_interval_s: float = 5.0  # the console's progress line at most this often


@dataclass
class TrackerLoggerConfig(LoggerConfig):
    """``logger=wandb`` / ``logger=mlflow``: TensorBoard plus a tracker
    (``rlgrasp.train.tracking.trackers``)."""

    project: str = "rlgrasp"  # W&B project / MLflow experiment
    tags: list[str] = field(default_factory=list)  # run tags in the tracker's UI
    run_name: str | None = None  # null: <experiment_name>/<run dir name>


@dataclass
class WandbLoggerConfig(TrackerLoggerConfig):
    _target_: str = "rlgrasp.train.tracking.trackers.WandbLogger"
    entity: str | None = None  # W&B team or user (null: your default)
    # online | offline | disabled (null: $WANDB_MODE, else online).
    mode: str | None = None


@dataclass
class MlflowLoggerConfig(TrackerLoggerConfig):
    _target_: str = "rlgrasp.train.tracking.trackers.MlflowLogger"
    # A server (http://...), a database (sqlite:///...) or a folder (file:...); null: $MLFLOW_TRACKING_URI,
    # else the folder outputs/mlruns.
    tracking_uri: str | None = None
