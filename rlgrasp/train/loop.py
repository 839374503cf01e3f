"""The training loop: collect, update, log, evaluate, checkpoint; resume and fault handling."""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from rlgrasp.stats import wilson_interval
from rlgrasp.train import checkpoint as ckpt_lib
from rlgrasp.train.collect import build_collector, make_batched_env, read_env_errors
from rlgrasp.train.evaluate import Evaluator
from rlgrasp.train.logger import RunLogger, flatten, log, progress_line, setup_text_log
from rlgrasp.train.models import OBS_KEY, build_models
from rlgrasp.train.ppo import NonFiniteError, PPOLearner


class TrainingError(RuntimeError):
    """Training stopped on a fault (env crash, NaN); the message says what and where."""


def resolve_device(device: str) -> torch.device:
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


def frames_per_batch(cfg: Any) -> int:
    c = cfg.collector
    workers = 1 if c.backend == "single" or c.num_workers == 0 else c.num_workers
    return workers * c.envs_per_worker * c.steps_per_env


def _env_spec(env_cfg: dict[str, Any], vector: str = "gym_sync") -> dict[str, Any]:
    """Observation/action sizes and bounds, from one throw-away env built like the workers' ones."""
    env = make_batched_env(env_cfg, 1, 0, episode_stats=False, seed_torch=False, vector=vector)
    try:
        obs_dim = int(env.observation_spec[OBS_KEY].shape[-1])
        action_spec = env.action_spec
        low = action_spec.space.low.flatten().tolist()
        high = action_spec.space.high.flatten().tolist()
    finally:
        env.close()
    return {
        "obs_key": OBS_KEY,
        "obs_dim": obs_dim,
        "action_dim": len(low),
        "action_low": low,
        "action_high": high,
    }


def _config_diff(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    a, b = flatten(old), flatten(new)
    return [f"{k}: {a.get(k)!r} -> {b.get(k)!r}" for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]


class _Due:
    """True once every ``interval`` frames (interval <= 0: never)."""

    def __init__(self, interval: int, frames: int) -> None:
        self.interval = interval
        self.mark = frames // interval if interval > 0 else 0

    def __call__(self, frames: int) -> bool:
        if self.interval <= 0 or frames // self.interval <= self.mark:
            return False
        self.mark = frames // self.interval
        return True


#: Called after each evaluation with (frames, metrics); see ``train``.
EvalCallback = Callable[[int, dict[str, float]], None]


def train(cfg: DictConfig, on_eval: EvalCallback | None = None) -> float:
    """Train PPO as configured; returns the final evaluation success rate (NaN if the env has none).

    Raises ``TrainingError`` on an env crash (after saving a checkpoint) or a NaN/inf (keeping the
    last good checkpoint). Ctrl-C saves a checkpoint and returns normally.

    ``on_eval(frames, metrics)`` runs after every evaluation (periodic and final); a sweep uses it to
    report to its pruner. An exception it raises (e.g. ``optuna.TrialPruned``) stops training: a
    checkpoint is saved, workers are shut down, and the exception propagates unchanged.
    """
    run_dir = Path(cfg.paths.output_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    setup_text_log(run_dir)
    ckpt_dir = run_dir / "checkpoints"
    error_dir = run_dir / "env_errors"
    config = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(config, dict)
    device = resolve_device(cfg.device)
    torch.set_num_threads(cfg.collector.torch_threads)

    resumed = ckpt_lib.load_checkpoint(cfg.resume, map_location=device) if cfg.resume else None
    random.seed(cfg.seed)
    np.random.seed(cfg.seed)
    torch.manual_seed(cfg.seed)

    env_cfg = dict(config["env"])
    spec = _env_spec(env_cfg, cfg.collector.vector)
    actor, critic, norm = build_models(
        spec["obs_dim"], torch.tensor(spec["action_low"]), torch.tensor(spec["action_high"]), cfg.model
    )
    actor, critic = actor.to(device), critic.to(device)
    learner = PPOLearner(actor, critic, norm, cfg.algo, device)

    frames, updates, generation = 0, 0, 0
    best_success, last_eval = -math.inf, None
    if resumed is not None:
        for line in _config_diff(resumed["config"], config):
            if not line.startswith(("resume", "paths.", "total_frames", "time_budget_min")):
                log.warning("resume: config differs from the checkpoint's: %s", line)
        actor.load_state_dict(resumed["actor"])
        critic.load_state_dict(resumed["critic"])
        learner.optimizer.load_state_dict(resumed["optimizer"])
        ckpt_lib.set_rng_state(resumed["rng"])
        frames, updates = resumed["frames"], resumed["updates"]
        generation = resumed.get("generation", 0) + 1
        best_success = resumed.get("best_eval_success", -math.inf)
        last_eval = resumed.get("last_eval")
        log.info("resumed from %s at %s frames", cfg.resume, f"{frames:,}")

    def state() -> dict[str, Any]:
        return {
            "format": ckpt_lib.FORMAT,
            "actor": actor.state_dict(),
            "critic": critic.state_dict(),
            "obs_norm": norm.state_dict(),
            "optimizer": learner.optimizer.state_dict(),
            "frames": frames,
            "updates": updates,
            "generation": generation,
            "best_eval_success": best_success,
            "last_eval": last_eval,
            "rng": ckpt_lib.rng_state(),
            "config": config,
            "spec": spec,
            "versions": ckpt_lib.package_versions(),
            "run_dir": str(run_dir),
        }

    def save(is_best: bool = False) -> None:
        path = ckpt_lib.write_checkpoints(ckpt_dir, state(), cfg.checkpoint.keep_last, is_best)
        log.info("checkpoint %s", path)

    logger = RunLogger(
        run_dir / "tensorboard", cfg.logger.backend, purge_step=frames + 1 if resumed else None
    )
    if resumed is None:
        logger.text("config", OmegaConf.to_yaml(config), 0)
    evaluator = Evaluator(
        env_cfg, cfg.eval.episodes, cfg.eval.num_envs, cfg.seed * 1_000_003 + cfg.eval.seed_offset
    )

    final_episodes = cfg.eval.final_episodes or cfg.eval.episodes

    def evaluate(final: bool = False) -> dict[str, float]:
        nonlocal best_success, last_eval
        t0 = time.perf_counter()
        episodes = final_episodes if final else cfg.eval.episodes
        actor.eval()
        result = evaluator.run(actor, episodes)
        actor.train()
        result["frames"] = frames
        last_eval = result
        logger.scalars({f"eval/{k}": v for k, v in result.items() if k != "frames"}, frames)
        logger.scalars({"time/eval_s": time.perf_counter() - t0}, frames)
        score = result.get("success_rate", result["mean_reward"])
        is_best = score > best_success
        if is_best:
            best_success = score
        log.info("eval at %s frames: %s", f"{frames:,}", {k: round(v, 3) for k, v in result.items()})
        if final and "success_rate" in result:
            wins = round(result["success_rate"] * episodes)
            low, high = wilson_interval(wins, episodes)
            log.info("final eval: success %d/%d [95%% Wilson %.3f, %.3f]", wins, episodes, low, high)
        if on_eval is not None:
            try:
                on_eval(frames, dict(result))
            except BaseException as exc:
                log.warning("stopped by the eval callback at %s frames: %r", f"{frames:,}", exc)
                save(is_best)
                raise
        return {"is_best": is_best}

    fpb = frames_per_batch(cfg)
    total = cfg.total_frames
    budget_s = cfg.time_budget_min * 60 if cfg.time_budget_min else math.inf
    eval_due = _Due(cfg.eval.interval_frames, frames)
    ckpt_due = _Due(cfg.checkpoint.interval_frames, frames)
    log.info(
        "run dir %s | device %s | %d frames per batch (%s) | %s",
        run_dir,
        device,
        fpb,
        cfg.collector.backend,
        spec,
    )

    collector = None
    status = "running"
    start = last_console = time.monotonic()
    session_frames = 0
    sps_t0, sps_frames0 = None, 0  # SPS is measured from the first batch on (spawn excluded)
    recent_success = recent_return = None
    try:
        collector = build_collector(cfg, actor, fpb, generation, str(error_dir))
        batches = iter(collector)
        while frames < total and time.monotonic() - start < budget_s:
            t0 = time.perf_counter()
            try:
                batch = next(batches)
            except (KeyboardInterrupt, StopIteration):
                raise
            except Exception as exc:
                status = "env_error"
                save()
                time.sleep(0.5)  # let the failing worker finish writing its report
                reports = read_env_errors(error_dir) or [f"{type(exc).__name__}: {exc}"]
                raise TrainingError(
                    f"collection failed at {frames:,} frames; checkpoint saved in {ckpt_dir}\n  "
                    + "\n  ".join(reports)
                ) from exc
            collect_s = time.perf_counter() - t0
            batch = batch.reshape(-1, batch.shape[-1])
            frames += batch.numel()
            session_frames += batch.numel()
            metrics: dict[str, float] = {"time/collect_s": collect_s}
            ep = _finished_episodes(batch)
            if ep:
                metrics.update(ep)
                recent_return = ep["charts/episodic_return"]
                recent_success = ep.get("charts/success_rate", recent_success)

            t1 = time.perf_counter()
            lr = learner.lr_at(frames, total)
            learner.set_lr(lr)
            losses = learner.update(batch)
            collector.update_policy_weights_()
            updates += 1
            metrics["time/train_s"] = time.perf_counter() - t1
            elapsed = time.monotonic() - start
            now = time.perf_counter()
            if sps_t0 is None:  # the first batch includes the workers' start-up
                sps = batch.numel() / max(now - t0, 1e-9)
                sps_t0, sps_frames0 = now, session_frames
            else:
                sps = (session_frames - sps_frames0) / max(now - sps_t0, 1e-9)
            metrics.update({f"losses/{k}": v for k, v in losses.items()})
            metrics["charts/learning_rate"] = lr
            metrics["charts/SPS"] = sps
            logger.scalars(metrics, frames)

            is_best = False
            if eval_due(frames) and frames < total:  # at the end the final evaluation runs
                is_best = evaluate()["is_best"]
            if ckpt_due(frames) or is_best:
                save(is_best)
            if time.monotonic() - last_console >= cfg.logger.console_interval_s:
                last_console = time.monotonic()
                eta = min((total - frames) / max(sps, 1e-9), budget_s - elapsed)
                eval_s = last_eval.get("success_rate") if last_eval else None
                log.info(progress_line(frames, total, sps, recent_success, recent_return, eval_s, eta))
                logger.flush()
        status = "done"
    except KeyboardInterrupt:
        status = "interrupted"
        log.warning("interrupted at %s frames: saving a checkpoint", f"{frames:,}")
        save()
    except NonFiniteError as exc:
        status = "non_finite"
        raise TrainingError(
            f"{exc} at {frames:,} frames; stopped without saving, the last good checkpoint is "
            f"{ckpt_dir / 'last.pt'}"
        ) from exc
    finally:
        if collector is not None:
            try:
                collector.shutdown()
            except Exception as exc:  # noqa: BLE001 - a dead worker can make shutdown complain
                log.warning("collector shutdown: %s", exc)
        if status != "done":
            evaluator.close()
            logger.close()

    if status == "interrupted":
        return float((last_eval or {}).get("success_rate", float("nan")))
    try:
        if last_eval is None or last_eval["frames"] != frames or final_episodes > cfg.eval.episodes:
            save(evaluate(final=True)["is_best"])
        elif not (ckpt_dir / "last.pt").exists() or ckpt_lib.load_checkpoint(run_dir)["frames"] != frames:
            save()
    except BaseException:  # the eval callback stopped the run (it saved a checkpoint)
        evaluator.close()
        logger.close()
        raise
    evaluator.close()
    result = last_eval or {}
    success = float(result.get("success_rate", float("nan")))
    logger.hparams(
        flatten(config),
        {
            "hparam/eval_success_rate": success,
            "hparam/eval_mean_reward": result.get("mean_reward", float("nan")),
        },
    )
    logger.close()
    log.info("finished at %s frames (%s): eval %s", f"{frames:,}", status, result)
    return success


def _finished_episodes(batch) -> dict[str, float]:
    """Return, length and success-at-episode-end of the episodes that ended in this batch."""
    done = batch["next", "done"].reshape(batch.shape)
    if not done.any():
        return {}
    out = {}
    if ("next", "episode_reward") in batch.keys(True):
        out["charts/episodic_return"] = float(
            batch["next", "episode_reward"].reshape(batch.shape)[done].mean()
        )
    if ("next", "step_count") in batch.keys(True):
        out["charts/episodic_length"] = float(
            batch["next", "step_count"].reshape(batch.shape)[done].float().mean()
        )
    if ("next", "is_success") in batch.keys(True):
        out["charts/success_rate"] = float(
            batch["next", "is_success"].reshape(batch.shape)[done].float().mean()
        )
    out["charts/episodes"] = float(done.sum())
    return out
