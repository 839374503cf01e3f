"""Starting or resuming a run: which checkpoint, which config, which keys may change.

``resume=<run dir>`` (or a checkpoint file) continues the run as it was launched: the checkpoint's
resolved config is the base and only what the command line changes is applied on top. Keys in
``MUTABLE`` may change (and are logged); any other change is refused with one line naming the key
and both values, before any worker starts. A ``_target_`` node whose class changes (``collector=ray``
on a process run) keeps only the keys of its new class. ``resume=auto`` continues the run directory's newest
readable checkpoint when there is one and starts fresh otherwise (``rlgrasp.rundir.run_dir`` picks
the newest run of the same experiment and seed as the run directory). A job SLURM runs again after a
requeue (``SLURM_RESTART_COUNT`` > 0) resumes as with ``resume=auto`` when no ``resume`` was given.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from hydra import compose
from hydra.core.global_hydra import GlobalHydra
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import DictConfig, OmegaConf

from rlgrasp import policy_file
from rlgrasp.compose import compose_train
from rlgrasp.config import CONFIG_DIR, ConfigError
from rlgrasp.legacy import algorithm_state
from rlgrasp.received import logger_name
from rlgrasp.rundir import CHECKPOINTS
from rlgrasp.train.validate import validate_train
from rlgrasp.utils import flatten

log = logging.getLogger("rlgrasp.train")

#: Keys (exact, or prefixes ending in ".") that may differ from the checkpoint's config on resume.
MUTABLE = (
    "resume",
    "paths.",
    "total_frames",
    "time_budget_min",
    "eval.interval_frames",
    "eval.episodes",
    "eval.final_episodes",
    "eval.num_envs",
    "eval.background",
    "checkpoint.interval_frames",
    "checkpoint.keep_last",
    "logger.",
    "collector.num_workers",
    "collector._target_",
    "collector.torch_threads",
    "collector.overlap",
    "collector.worker_timeout_s",
    "collector.ray.",
    "device",
)
_QUIET = ("resume", "paths.")  # expected to differ: not worth a log line
_ABSENT = object()


def _mutable(key: str) -> bool:
    return any(key == m or (m.endswith(".") and key.startswith(m)) for m in MUTABLE)


def prepare_run(cfg: DictConfig, changed: Iterable[str] | None = None) -> tuple[DictConfig, dict | None]:
    """The config to train with and the checkpoint to continue from (None: a fresh run).

    ``changed``: the keys the command line set (None: every key of ``cfg`` counts as set).
    Raises ``ConfigError`` / ``CheckpointError`` with a one-line message.
    """
    run_dir = Path(cfg.paths.output_dir)
    resume = cfg.resume or requeued_resume()
    has_ckpts = bool(policy_file.checkpoint_files(run_dir / CHECKPOINTS))
    if resume == "auto":
        source = run_dir if has_ckpts else None
        if source is None:
            log.info("resume=auto: no checkpoint in %s, starting fresh", run_dir)
    elif resume:
        source = Path(resume).expanduser()
        if not source.exists():
            raise ConfigError(f"resume={resume}: no such file or directory")
    else:
        if has_ckpts:
            raise ConfigError(
                f"run directory {run_dir} already holds checkpoints: continue it with resume={run_dir} "
                "(or resume=auto), or start the new run elsewhere"
            )
        source = None
    if source is None:
        run_cfg, state = cfg, None
    else:
        user = OmegaConf.to_container(cfg, resolve=False)
        path, state = _resumed_state(source, resume, user)
        run_cfg = _resumed_config(cfg, state, resume, changed, user)
    validate_train(run_cfg)  # once, whichever config the run goes on with
    if state is not None:
        log.info("resuming from %s (%s frames)", path, f"{state['frames']:,}")
    return run_cfg, state


def _resumed_state(source: Path, resume: str, user: dict) -> tuple[Path, dict]:
    """``(path, state)`` of the checkpoint ``resume`` continues, refused in one line when it holds no
    training state. Its config is data; a class of the user's own (``user``: the command line's
    config, unresolved) is one their own config names at that node."""
    if source.is_dir():
        path, state = policy_file.newest_readable(source, user=user)
    else:
        path, state = source, policy_file.read_checkpoint(source, user=user)
    if "rng" not in state or "frames" not in state or algorithm_state(state) is None:
        raise ConfigError(
            f"resume={resume}: {path} is a policy file (no training state to continue); resume takes a "
            f"run directory or its checkpoint; to start a new run from this policy: algo.init_from={path}"
        )
    return path, state


def _resumed_config(
    cfg: DictConfig, state: dict, resume: str, changed: Iterable[str] | None, user: dict
) -> DictConfig:
    """The checkpoint's config with the command line's changes (``merged_config``), logging where
    the command line says (never a file's logger: where the curves go is the user's to say)."""
    merged = merged_config(cfg, state["config"], changed)
    merged.logger = cfg.logger
    theirs, ours = logger_name(state["config"]), logger_name({"logger": user.get("logger")})
    if theirs and theirs != ours:
        log.info(
            "resume: logging with this command line's logger (%s), not the checkpoint's (%s)", ours, theirs
        )
    merged.resume = resume  # what it resumed with, also when a requeue chose it
    return merged


def requeued_resume() -> str | None:
    """``auto`` in a job SLURM requeued (preemption, ``scontrol requeue``, submitit's requeue): it runs
    the command line of its first start again, in the same run directory, which now holds that
    start's checkpoints; without this it would refuse to start there."""
    restarts = int(os.environ.get("SLURM_RESTART_COUNT") or 0)
    if restarts <= 0:
        return None
    log.info("SLURM restart %d of this job: resume=auto", restarts)
    return "auto"


def merged_config(cfg: DictConfig, saved: dict[str, Any], changed: Iterable[str] | None) -> DictConfig:
    """The checkpoint's config ``saved`` with the command line's changes applied; a change of a key
    outside ``MUTABLE`` raises ``ConfigError`` naming the key and both values."""
    given = flatten(OmegaConf.to_container(cfg, resolve=True))
    old = flatten(saved)
    if changed is None:
        keys = set(given)
    else:
        prefixes = tuple(f"{k}." for k in changed)
        keys = {k for k in given if k in set(changed) or k.startswith(prefixes)}
    keys |= {k for k in given if k.startswith(_QUIET)}
    base = OmegaConf.create(saved)
    refused = []
    for key in sorted(keys):
        new, prev = given[key], old.get(key, _ABSENT)
        if new == prev:
            continue
        if prev is _ABSENT and _reshaped(key, old):
            prev = _value_around(key, old)
        if prev is not _ABSENT and not _mutable(key):
            refused.append(f"{key}: the checkpoint has {prev!r}, the command line {new!r}")
            continue
        OmegaConf.update(base, key, new, force_add=True)
        if not key.startswith(_QUIET) and prev is not _ABSENT:
            log.info("resume: %s: %r -> %r", key, prev, new)
    if refused:
        more = f" (and {len(refused) - 1} more)" if len(refused) > 1 else ""
        raise ConfigError(
            f"cannot change on resume: {refused[0]}{more}; on resume only these may change: "
            + ", ".join(m.rstrip(".") for m in MUTABLE if m not in _QUIET)
        )
    for key in sorted(k for k in keys if k.endswith("._target_") and given[k] != old.get(k, given[k])):
        _drop_keys_of_the_old_class(base, key.removesuffix("._target_"), old, given)
    return base


def _drop_keys_of_the_old_class(
    base: DictConfig, node: str, old: dict[str, Any], given: dict[str, Any]
) -> None:
    """Remove from ``base``'s ``node`` the keys (first level) the command line's node does not have:
    the old class's own keys, which the new class would refuse."""

    def children(flat: dict[str, Any]) -> set[str]:
        return {k[len(node) + 1 :].split(".")[0] for k in flat if k.startswith(node + ".")}

    target = OmegaConf.select(base, node)
    for child in children(old) - children(given):
        del target[child]


def _reshaped(key: str, old: dict[str, Any]) -> bool:
    """A key absent from the checkpoint because a value there is a mapping here, or the reverse
    (``env.randomization: default`` vs ``{object_mass: ...}``), not because the schema grew."""
    parts = key.split(".")
    return any(".".join(parts[:i]) in old for i in range(1, len(parts))) or any(
        k.startswith(key + ".") for k in old
    )


def _value_around(key: str, old: dict[str, Any]) -> Any:
    parts = key.split(".")
    for i in range(len(parts) - 1, 0, -1):
        if ".".join(parts[:i]) in old:
            return old[".".join(parts[:i])]
    return {k[len(key) + 1 :]: v for k, v in old.items() if k.startswith(key + ".")}


def command_line_keys(task_overrides: list[str], cfg: DictConfig) -> set[str]:
    """The config keys a Hydra command line sets: its ``key=value`` keys, plus the keys whose value
    its group choices (``experiment=``, ``collector=``, ...) change from the defaults."""
    keys, groups = set(), []
    for override in OverridesParser.create().parse_overrides(task_overrides):
        name = override.key_or_group
        if name.startswith("hydra") or override.is_delete():
            continue
        if (Path(CONFIG_DIR) / name).is_dir():
            groups.append(override.input_line)
            keys |= {k for k in _keys_written_by(name, override.value()) if not _mutable(k)}
        else:
            keys.add(name)
    if groups:
        keys |= _keys_changed_by(groups, cfg)
    return keys


def _keys_written_by(group: str, choice: Any) -> set[str]:
    """The keys the group's chosen file writes itself (not its defaults list), at its package.

    A choice equal to the default changes no key, so ``_keys_changed_by`` cannot see it: ``robot=panda``
    on an iiwa run must still count as setting ``env.robot``. Only fixed keys are added by the caller,
    so this can refuse a resume but never silently revert a mutable key the launch had changed.
    """
    path = Path(CONFIG_DIR) / group / f"{choice}.yaml"
    if not isinstance(choice, str) or not path.is_file():
        return set()
    text = path.read_text()
    header = re.search(r"^#\s*@package\s+(\S+)", text, flags=re.M)
    package = header.group(1) if header else group.replace("/", ".")
    prefix = "" if package == "_global_" else f"{package}."
    node = OmegaConf.to_container(OmegaConf.create(text), resolve=False) or {}
    node.pop("defaults", None)
    return {prefix + k for k in flatten(node)}


def _keys_changed_by(groups: list[str], cfg: DictConfig) -> set[str]:
    """Keys whose value differs between the defaults and the defaults with these group choices."""
    fixed = [f"paths.output_dir={cfg.paths.output_dir}"]
    try:
        if GlobalHydra.instance().is_initialized():
            default, chosen = (compose("train", overrides=fixed + g) for g in ([], groups))
        else:
            default, chosen = (compose_train(fixed + g) for g in ([], groups))
    except Exception as exc:  # noqa: BLE001 - fall back to the strict comparison
        log.warning("resume: could not compose %s alone (%s); comparing every key", groups, exc)
        return set(flatten(OmegaConf.to_container(cfg, resolve=True)))
    a = flatten(OmegaConf.to_container(default, resolve=True))
    b = flatten(OmegaConf.to_container(chosen, resolve=True))
    return {k for k in set(a) | set(b) if a.get(k, _ABSENT) != b.get(k, _ABSENT)}
