"""Reading one setting of an env config as a checkpoint, a run folder or a teacher gives it: a config
may leave a part to its defaults, so a missing node or key reads as ``EnvConfig``'s default.

Apart from ``rlgrasp.envs.part_config`` (which the env itself imports to read its parts) because it
reads ``EnvConfig``, the env's schema: there it made the two modules import each other."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlgrasp.envs.grasp_env import EnvConfig

#: The env settings that change what an action means: a policy acts in an env only if they agree
#: (a teacher, a warm start, a DAgger teacher).
ACTION_SETTINGS = ("control.mode", "control.ee_yaw")

#: ``env_setting``'s default: the value ``EnvConfig`` gives the path.
SCHEMA_DEFAULT = object()


def env_setting(env_cfg: Mapping[str, Any], path: str, default: Any = SCHEMA_DEFAULT) -> Any:
    """The value at a dotted ``path`` of an env config (``control.mode``, ``sim.substeps``); where a
    node or the key is missing (a config may leave a part to its defaults), ``default``, by default
    the one ``EnvConfig`` declares (``None`` for a path it does not have)."""
    node: Any = env_cfg
    for key in path.split("."):
        if not isinstance(node, Mapping) or key not in node or node[key] is None:
            return _schema_default(path) if default is SCHEMA_DEFAULT else default
        node = node[key]
    return node


def _schema_default(path: str) -> Any:
    node: Any = EnvConfig()
    for key in path.split("."):
        node = getattr(node, key, None)
    return node
