"""The learner's allocator setting (``rlgrasp.utils.keep_freed_memory``): glibc takes it, anything
else is left as it is."""

from __future__ import annotations

import platform
import subprocess
import sys


def test_keep_freed_memory_is_taken_by_glibc_and_refused_elsewhere() -> None:
    # In a process of its own: the setting lasts as long as the process that makes it.
    code = "from rlgrasp.utils import keep_freed_memory; print(keep_freed_memory())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == str(platform.libc_ver()[0] == "glibc")
