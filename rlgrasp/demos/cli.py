"""Console entry point ``rlgrasp-demos`` (same as ``python scripts/demos.py``): record demonstrations.

Everything is checked (the policy, the env, the output location) before a worker starts; bad input
ends with one line, exit code 2, and nothing written.
"""

from __future__ import annotations

import json
import logging
import signal
import sys
from pathlib import Path
from typing import Any

import hydra
from omegaconf import DictConfig, OmegaConf

from rlgrasp.config import CONFIG_DIR, register_configs
from rlgrasp.demos.dataset import LAYOUT_KEYS, layout_of, summary, write_demos
from rlgrasp.demos.record import record, to_frames
from rlgrasp.envs.env_settings import env_setting
from rlgrasp.envs.factory import env_factory
from rlgrasp.evaluation.policies import PolicySource
from rlgrasp.overrides import entry_point, unwritable
from rlgrasp.policy_file import CheckpointError, load_checkpoint
from rlgrasp.utils import Progress, WorkerDiedError, sigterm_as_interrupt

register_configs()
log = logging.getLogger("rlgrasp.demos")
#: What a worker needs of a checkpoint (not the optimizer state).
POLICY_KEYS = ("actor", "spec", "config", "kind")


class DemosInputError(ValueError):
    """Bad input to rlgrasp-demos; the message is one line."""


def _source(cfg: DictConfig) -> tuple[PolicySource, dict[str, Any]]:
    """The policy and env the workers rebuild, and the file's layout (from one dry-run env)."""
    env_cfg = OmegaConf.to_container(cfg.env, resolve=True)
    try:
        env = env_factory(env_cfg)()
    except (ValueError, TypeError, OSError) as exc:
        raise DemosInputError(f"env: {str(exc).splitlines()[0]}") from None
    try:
        layout = layout_of(env, env_cfg)
    finally:
        env.close()
    if cfg.policy == "scripted":
        mode = env_setting(env_cfg, "control.mode")
        if mode != "ee_delta":
            raise DemosInputError(
                f"env.control.mode={mode}: the scripted expert acts in ee_delta "
                "(or give policy=<checkpoint> of a policy trained in this mode)"
            )
        return PolicySource("scripted", env_cfg), layout
    try:
        ckpt = load_checkpoint(cfg.policy)
    except CheckpointError as exc:
        raise DemosInputError(f"policy={cfg.policy}: {exc}") from None
    theirs = ckpt["config"]["env"]
    for path in LAYOUT_KEYS.values():
        if env_setting(theirs, path) != env_setting(env_cfg, path):
            raise DemosInputError(
                f"policy={cfg.policy}: trained with env.{path}={env_setting(theirs, path)!r}, "
                f"this env has {env_setting(env_cfg, path)!r}"
            )
    if ckpt["spec"]["obs_dim"] != layout["obs_dim"] or ckpt.get("kind") == "vision":
        raise DemosInputError(f"policy={cfg.policy}: it does not read this env's observation vector")
    trimmed = {k: ckpt[k] for k in POLICY_KEYS if k in ckpt}
    return PolicySource("checkpoint", env_cfg, ckpt=trimmed, ckpt_path=str(cfg.policy)), layout


def _check(cfg: DictConfig) -> None:
    checks = [
        ("episodes", cfg.episodes, cfg.episodes >= 1, "must be at least 1"),
        ("workers", cfg.workers, cfg.workers >= 1, "must be at least 1"),
        ("seed", cfg.seed, cfg.seed >= 0, "must be at least 0"),
        ("keep", cfg.keep, cfg.keep in ("success", "all"), "must be success or all"),
    ]
    for key, value, ok, allowed in checks:
        if not ok:
            raise DemosInputError(f"{key}={value}: {allowed}")
    where = Path(cfg.out) / "demos"
    if where.exists():
        raise DemosInputError(f"out={cfg.out}: {where} exists already (choose another out)")
    reason = unwritable(where, folder=True)
    if reason:
        raise DemosInputError(f"out={cfg.out}: cannot write there ({reason})")


def record_demos(cfg: DictConfig) -> dict[str, Any]:
    """Validate, record, write ``<out>/demos``; returns the summary."""
    _check(cfg)
    source, layout = _source(cfg)
    who = source.ckpt_path or "the scripted expert"
    log.info("recording %d episodes of %s with %d worker(s)", cfg.episodes, who, cfg.workers)
    episodes = record(source, cfg.episodes, cfg.seed, cfg.workers, Progress(log))
    for e in episodes:
        e["kept"] = cfg.keep == "all" or e["success"]
    kept = [e for e in episodes if e["kept"]]
    info = summary(episodes, len(kept))
    meta = {
        **layout,
        "policy": cfg.policy,
        "keep": cfg.keep,
        "seed": cfg.seed,
        "env": OmegaConf.to_container(cfg.env, resolve=True),
        "summary": info,
    }
    path = write_demos(Path(cfg.out), to_frames(kept), meta)
    (Path(cfg.out) / "summary.json").write_text(json.dumps(info, indent=1))
    log.info(
        "success %.3f over %d episodes; kept %d (%d frames); length mean %.1f [%d, %d]; %s",
        info["success_rate"],
        info["episodes"],
        info["kept"],
        info["frames"],
        info["mean_length"],
        info["min_length"],
        info["max_length"],
        _objects_line(info["objects"], cfg.out),
    )
    log.info("wrote %s (train with algo.demos=%s)", path, path)
    return info


def _objects_line(objects: dict[str, Any], out: str, most: int = 8) -> str:
    """Success per object on the console, or, for a mesh set's hundreds, where to find it."""
    if len(objects) <= most:
        return "objects " + json.dumps(objects)
    return f"{len(objects)} objects (success per object: {out}/summary.json)"


@entry_point("demos")  # objects={paths:[...]} as in training; a refused command line in one line
@hydra.main(config_path=CONFIG_DIR, config_name="demos", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Bad input exits 2, a dead worker 1, Ctrl-C or SIGTERM 128 + the signal's number, each with one
    line; a signal terminates the worker pool on its way out (SIGTERM's default would orphan it)."""
    with sigterm_as_interrupt() as caught:
        try:
            record_demos(cfg)
        except DemosInputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            sys.exit(2)
        except WorkerDiedError as exc:
            print(f"error: {exc}; nothing was written", file=sys.stderr)
            sys.exit(1)
        except KeyboardInterrupt:
            sig = signal.Signals(caught[0] if caught else signal.SIGINT)
            print(f"error: stopped by {sig.name}; nothing was written", file=sys.stderr)
            sys.exit(128 + sig)


if __name__ == "__main__":
    main()
