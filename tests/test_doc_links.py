"""Every docs/ page the code, configs and scripts name exists (mkdocs build --strict checks the links
between pages, not the ones in comments and docstrings)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = re.compile(r"docs/[\w./-]+\.md")


def test_pages_named_in_the_code_exist():
    missing = []
    for folder in ("rlgrasp", "scripts", "benchmarks", "configs", "examples", "hydra_plugins"):
        for path in sorted((ROOT / folder).rglob("*")):
            if path.suffix not in (".py", ".yaml", ".yml", ".sh") or not path.is_file():
                continue
            for page in set(PAGE.findall(path.read_text(errors="replace"))):
                if not (ROOT / page).is_file():
                    missing.append(f"{path.relative_to(ROOT)}: {page}")
    assert not missing, "pages that do not exist:\n" + "\n".join(missing)
