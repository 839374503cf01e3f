"""A newcomer's first half hour, timed: the README's own commands, run as written, one after another.

    python benchmarks/newcomer.py [--timeout 900] [--dry-run]

Run it in a fresh clone after installing as the README says (``.ci/run`` builds such a virtualenv:
``. .ci-venv/bin/activate``). Each command must appear verbatim in README.md (a README edit that
drops or changes one fails here before anything runs); each runs from the checkout's root with the
shell, and the table gives its seconds and exit status. Exits 1 if any command failed.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: The path: watch the expert, evaluate and export a shipped SAC policy, run the exported file,
#: train the smoke run. In the README's own words.
COMMANDS = [
    "rlgrasp-demo --episodes 3",
    "python scripts/evaluate.py ckpt=policies/pick_place_sac.pt episodes=20",
    "python scripts/export.py ckpt=policies/pick_place_sac.pt format=pt2 out=/tmp/pick_place.pt2",
    "python examples/run_exported_policy.py /tmp/pick_place.pt2",
    "python scripts/train.py experiment=smoke",
]


def missing_from_readme(commands: list[str], readme: Path = ROOT / "README.md") -> list[str]:
    """The commands that README.md does not spell exactly so (the ones a reader cannot copy)."""
    text = readme.read_text()
    return [c for c in commands if c not in text]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds a command may take")
    parser.add_argument("--dry-run", action="store_true", help="only check the README spells each")
    args = parser.parse_args(argv)
    missing = missing_from_readme(COMMANDS)
    if missing:
        print("not in README.md as written: " + "; ".join(missing))
        return 1
    if args.dry_run:
        print(f"all {len(COMMANDS)} commands are in README.md as written")
        return 0
    rows = []
    for command in COMMANDS:
        start = time.monotonic()
        try:
            code = subprocess.run(command, shell=True, cwd=ROOT, timeout=args.timeout).returncode
        except subprocess.TimeoutExpired:
            code = "timeout"
        rows.append((command, time.monotonic() - start, code))
    print("\n| command | seconds | exit |\n|---|---|---|")
    for command, seconds, code in rows:
        print(f"| `{command}` | {seconds:.0f} | {code} |")
    return 0 if all(code == 0 for _, _, code in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
