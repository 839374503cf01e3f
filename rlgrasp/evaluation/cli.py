"""Console entry point ``rlgrasp-eval`` (same as ``python scripts/evaluate.py``).

Order matters for "nothing written on bad input": resolve and validate the checkpoint, the env and
the output location first; create the output directory only once episodes have run.
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import sys
import tempfile
from datetime import datetime
from pathlib import Path
from typing import Any

import hydra
from omegaconf import DictConfig, OmegaConf

from rlgrasp.config import CONFIG_DIR, register_configs
from rlgrasp.envs import Randomizer
from rlgrasp.envs.env_settings import env_setting
from rlgrasp.evaluation import metrics as M
from rlgrasp.evaluation.episodes import episode_seeds, timed_run
from rlgrasp.evaluation.plots import (
    return_histogram,
    split_parameters,
    success_by_object_plot,
    success_by_parameter,
    success_table,
)
from rlgrasp.evaluation.policies import PolicySource
from rlgrasp.evaluation.source import EvaluationError, load_checked_checkpoint, prepare
from rlgrasp.evaluation.tb_log import log_to_tensorboard
from rlgrasp.evaluation.teacher import prepare_teacher
from rlgrasp.evaluation.video import video_format, write_video
from rlgrasp.overrides import entry_point, unwritable
from rlgrasp.received import ReceivedError, check_inside
from rlgrasp.rundir import name_problem
from rlgrasp.utils import Progress, WorkerDiedError, plain, sigterm_as_interrupt

log = logging.getLogger("rlgrasp.eval")

register_configs()


def output_dir(cfg: DictConfig, source: Any) -> Path:
    """``<run dir>/eval/<name>`` for a run's checkpoint, ``<outputs_root>/eval/<what>/<name>`` otherwise."""
    name = cfg.name or datetime.now().strftime("%Y-%m-%d_%H-%M-%S")
    if cfg.out_dir:
        return Path(cfg.out_dir)
    if source.run_dir:  # inside the run as given: never through a link in it (rlgrasp.received)
        out = Path(source.run_dir) / "eval" / name
        try:
            check_inside(source.run_dir, out, f"ckpt={cfg.ckpt}")
            if cfg.tensorboard:
                check_inside(source.run_dir, Path(source.run_dir) / "tensorboard", f"ckpt={cfg.ckpt}")
        except ReceivedError as exc:
            raise EvaluationError(str(exc)) from None
        return out
    what = source.kind if source.kind != "checkpoint" else Path(source.ckpt_path).stem
    return Path(cfg.outputs_root) / "eval" / what / name


def _randomization_ranges(spec: Any) -> dict[str, Any]:
    return {k: {"low": r.low, "high": r.high, "log": r.log} for k, r in Randomizer(spec).ranges.items()}


def evaluate(cfg: DictConfig) -> dict[str, Any]:
    """Validate, run the episodes (and the teacher's, on the same seeds), write every artefact;
    return ``metrics.json``'s content."""
    # --- validate everything before anything is written
    source, teacher, fmt, out = _validate(cfg)
    try:
        ranges = _randomization_ranges(source.env_cfg.get("randomization"))
    except ValueError as exc:
        raise EvaluationError(f"randomization: {exc}") from exc
    labels = conditions(source)
    log.info(
        "evaluating %s: %d episodes, seeds %d.., objects %s, randomization %s%s, %d worker(s), %s actions%s",
        source.ckpt_path or source.kind,
        cfg.episodes,
        cfg.seed,
        labels["objects"],
        labels["randomization"],
        "".join(f", {k} {labels[k]}" for k in ("camera", "visual") if k in labels),
        cfg.workers,
        "deterministic" if cfg.deterministic else "stochastic",
        f"; teacher {teacher.ckpt_path} on the same episodes" if teacher else "",
    )

    # --- run the episodes
    run = {
        "episodes": cfg.episodes,
        "base_seed": cfg.seed,
        "workers": cfg.workers,
        "deterministic": cfg.deterministic,
    }
    results, seconds = timed_run(
        source=source, video_episodes=cfg.video_episodes if fmt else 0, progress=Progress(log), **run
    )
    teacher_results: list = []
    if teacher:
        log.info("the teacher on the same %d episodes", cfg.episodes)
        teacher_results, teacher_seconds = timed_run(source=teacher, progress=Progress(log), **run)
        seconds += teacher_seconds
    metrics = _metrics(cfg, source, results, seconds, ranges)
    if teacher:
        metrics["teacher"] = M.compare_with_teacher(results, teacher_results, teacher.ckpt_path)
    table = metrics["summary_markdown"] = M.summary_table(metrics)

    files = _write_staged(out, cfg, source, (results, teacher_results), metrics, table, seconds, fmt)
    if cfg.tensorboard and source.run_dir:
        step = int((source.info or {}).get("frames") or 0)
        tb = log_to_tensorboard(source.run_dir, out.name, metrics, [r for r in results if r.frames], step)
        log.info("logged to TensorBoard %s (tags posthoc_eval/%s/*, eval_video/%s/*)", tb, out.name, out.name)
    log.info("files: %s", ", ".join(files))
    print(table)
    log.info("wrote %s in %.1f s", out, seconds)
    metrics["output_dir"] = str(out)
    return metrics


def _write_staged(
    out: Path,
    cfg: DictConfig,
    source: PolicySource,
    results: tuple,
    metrics: dict,
    table: str,
    seconds: float,
    fmt: str | None,
) -> list[str]:
    """Every artefact, written into a hidden staging folder renamed to ``out`` at the end, so that an
    evaluation is complete or absent."""
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        files = _write_artefacts(stage, out.name, cfg, source, results, metrics, table, seconds, fmt)
        if out.exists():  # an empty folder made in the meantime
            out.rmdir()
        os.replace(stage, out)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    return files


def _validate(cfg: DictConfig) -> tuple[PolicySource, PolicySource | None, str | None, Path]:
    """The policy source (checkpoint, env and policy checked), its teacher's if any, the video
    format, the output folder."""
    for key, minimum in (("episodes", 1), ("workers", 1), ("video_episodes", 0), ("seed", 0)):
        if cfg[key] < minimum:
            raise EvaluationError(f"{key}={cfg[key]}: must be at least {minimum}")
    if cfg.name is not None and name_problem("name", cfg.name):  # a folder of <run>/eval or outputs/eval
        raise EvaluationError(name_problem("name", cfg.name))
    fmt = None
    if cfg.video and cfg.video_episodes > 0:
        try:
            fmt = video_format(cfg.video_format)
        except ValueError as exc:
            raise EvaluationError(str(exc)) from exc
    source = prepare(cfg.policy, cfg.ckpt, cfg.ckpt_kind, plain(cfg.randomization), plain(cfg.env))
    teacher = prepare_teacher(cfg.teacher, source)
    out = output_dir(cfg, source)
    if (out / "metrics.json").exists():
        raise EvaluationError(f"{out} already holds an evaluation; pick another name=")
    problem = unwritable(out, folder=True)
    if problem:
        raise EvaluationError(f"cannot write the evaluation to {out}: {problem}")
    return source, teacher, fmt, out


def describe(spec: Any) -> str:
    """An objects or randomization spec as the command line would spell it (``{paths: [a.obj]}``)."""
    if isinstance(spec, dict):
        return "{" + ", ".join(f"{k}: {describe(v)}" for k, v in spec.items()) + "}"
    if isinstance(spec, (list, tuple)):
        return "[" + ", ".join(describe(v) for v in spec) + "]"
    return str(spec)


def conditions(source: Any) -> dict[str, str]:
    """The objects and the randomization the episodes use (for a camera env also the camera and the
    visuals), and whether the checkpoint trained on them: a held-out figure must say so, and so must
    one that is not."""
    paths = {"objects": "objects", "randomization": "randomization"}
    if source.env_cfg.get("camera"):
        paths.update(camera="camera", visual="sim.visual")
    labels, info = {}, source.info or {}
    for key, path in paths.items():
        used = describe(env_setting(source.env_cfg, path))
        trained = info.get(f"train_{key}")
        if trained is None and f"train_{key}" not in info:
            labels[key] = used
        else:
            trained = describe(trained)
            labels[key] = f"{used} (as trained)" if used == trained else f"{used} (trained on {trained})"
    return labels


def _metrics(cfg: DictConfig, source: Any, results: list, seconds: float, ranges: dict) -> dict[str, Any]:
    """``metrics.json``: the summary, what was evaluated and how, the timing."""
    randomization = source.env_cfg.get("randomization")
    labels = conditions(source)
    metrics = {
        "policy": source.kind,
        "policy_label": source.ckpt_path or source.kind,
        "objects_label": labels["objects"],
        "randomization_label": labels["randomization"],
        **{f"{k}_label": labels[k] for k in ("camera", "visual") if k in labels},
        **M.summarize(results),
        "seeds": episode_seeds(cfg.seed, cfg.episodes),
        "deterministic": bool(cfg.deterministic),
        "randomization": {"spec": randomization, "ranges": ranges},
        "checkpoint": source.info or None,
        "config": {"eval": OmegaConf.to_container(cfg, resolve=True), "env": source.env_cfg},
        "timing": {
            "seconds": round(seconds, 2),
            "workers": cfg.workers,
            "episodes_per_second": round(cfg.episodes / seconds, 2),
        },
    }
    if source.kind == "checkpoint":
        metrics["config"]["train"] = load_checked_checkpoint(Path(source.ckpt_path))["config"]
    return metrics


def _write_artefacts(
    out: Path,
    name: str,
    cfg: DictConfig,
    source: Any,
    runs: tuple[list, list],
    metrics: dict,
    table: str,
    seconds: float,
    fmt: str | None,
) -> list[str]:
    """metrics.json, episodes.csv, summary.md, plots and videos into ``out`` (the staging folder
    that becomes the evaluation ``name``). ``runs``: the episodes and the teacher's (or none)."""
    results, teacher = runs
    M.write_episodes_csv(out / "episodes.csv", results, teacher)
    M.write_objects_csv(out / "objects.csv", metrics)
    files = ["metrics.json", "episodes.csv", "objects.csv", "summary.md"]
    physics, visual = split_parameters(results)
    metrics["success_by_parameter"] = success_table(results, physics)
    if visual:  # what the camera saw: textures, light, camera pose, sensor noise
        metrics["success_by_visual"] = success_table(results, visual)
    if cfg.plots:
        success_by_parameter(results, out / "success_by_parameter.png", names=physics)
        return_histogram(results, out / "return_histogram.png")
        success_by_object_plot(metrics, out / "success_by_object.png")
        files += ["success_by_parameter.png", "return_histogram.png", "success_by_object.png"]
        if visual:
            success_by_parameter(
                results, out / "success_by_visual.png", names=visual, what="visual randomization"
            )
            files.append("success_by_visual.png")
    if fmt:
        step_s = env_setting(source.env_cfg, "sim.time_step") * env_setting(source.env_cfg, "sim.substeps")
        for r in results:
            if r.frames:
                path = write_video(
                    r, out / f"episode_{r.index:03d}_seed_{r.seed}", fps=round(1 / step_s), fmt=fmt
                )
                files.append(path.name)
    metrics["files"] = files
    M.write_json(out / "metrics.json", metrics)
    visual_section = (
        f"## Success per visual parameter, most influential first (all bins: metrics.json)\n\n"
        f"{M.parameter_table(metrics['success_by_visual'])}\n\n"
        if visual
        else ""
    )
    (out / "summary.md").write_text(
        f"# Evaluation {name}\n\n{table}\n\n## Outcomes\n\n{M.outcome_table(metrics)}\n\n"
        f"## Success per object, lowest first (all of them: objects.csv)\n\n{M.object_table(metrics)}\n\n"
        f"{visual_section}"
        f"Wall time {seconds:.1f} s on {cfg.workers} worker(s). Files: {', '.join(files)}\n"
    )
    return files


def run(cfg: DictConfig) -> float:
    """Evaluate; a bad input exits with code 2 and one clear line (no traceback); Ctrl-C or SIGTERM
    with 128 + the signal's number and one line, a worker that died with 1 and one line, each
    leaving no worker and no partial output behind."""
    with sigterm_as_interrupt() as caught:
        try:
            return float(evaluate(cfg)["success_at_end"]["rate"])
        except EvaluationError as exc:
            print(f"error: {exc}", file=sys.stderr)
            sys.exit(2)
        except KeyboardInterrupt:
            sig = signal.Signals(caught[0] if caught else signal.SIGINT)
            print(f"error: stopped by {sig.name}; the evaluation was not written", file=sys.stderr)
            sys.exit(128 + sig)
        except WorkerDiedError as exc:
            print(f"error: {exc}; the evaluation was not written", file=sys.stderr)
            sys.exit(1)


@entry_point("eval", open_env=True)
@hydra.main(config_path=CONFIG_DIR, config_name="eval", version_base="1.3")
def main(cfg: DictConfig) -> float:
    return run(cfg)


if __name__ == "__main__":
    main()
