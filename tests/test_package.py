"""What ``import rlgrasp`` does to the interpreter beyond defining names."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

PROBE = (
    "import importlib.util, sys; import rlgrasp; import tensordict; "
    "print(sys.modules.get('pandas', 'absent') is None, importlib.util.find_spec('pandas') is None)"
)


def _probe(extra_path: Path | None = None) -> str:
    env_path = [str(Path(__file__).resolve().parents[1])] + ([str(extra_path)] if extra_path else [])
    code = f"import sys; sys.path[:0] = {env_path!r}; " + PROBE
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return done.stdout.strip()


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_a_missing_pandas_is_marked_absent_and_an_installed_one_left_alone(tmp_path: Path) -> None:
    """TensorDict looks pandas up on every module call; without pandas, ``import rlgrasp`` makes
    that lookup a dictionary read (``None`` in ``sys.modules``). A pandas that is there stays
    importable."""
    (tmp_path / "pandas").mkdir()
    (tmp_path / "pandas" / "__init__.py").write_text("")
    assert _probe(tmp_path) == "False False"  # installed: neither marked nor hidden
    installed = subprocess.run([sys.executable, "-c", "import pandas"], capture_output=True).returncode == 0
    if not installed:
        assert _probe() == "True True"
