"""Every docs/ page the code, configs and scripts name exists (mkdocs build --strict checks the links
between pages, not the ones in comments and docstrings), and the links between pages reach their
anchors (so that a section moved without its links fails here, not only in the docs build)."""

import re
import unicodedata
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


def _slug(heading: str) -> str:
    """The anchor Python-Markdown's toc gives a heading (mkdocs' default): link text kept, code
    marks dropped, then its ``slugify``. An approximation for plain headings; `mkdocs build --strict`
    is the full check."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "")
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    return re.sub(r"[-\s]+", "-", re.sub(r"[^\w\s-]", "", text).strip().lower())


def _anchors(page: Path) -> set[str]:
    found, seen, fenced = set(), {}, False
    for line in page.read_text().splitlines():
        fenced ^= line.lstrip().startswith("```")
        heading = None if fenced else re.match(r"#{1,6}\s+(.*?)\s*$", line)
        if heading:
            slug = _slug(heading[1])
            seen[slug] = seen.get(slug, -1) + 1
            found.add(f"{slug}_{seen[slug]}" if seen[slug] else slug)
    return found


def test_links_between_pages_and_their_anchors_resolve():
    """Every relative link of docs/ and README.md reaches a page, and its #anchor a heading there:
    benchmark sections move (docs/benchmarks/log.md), and a link to the old place must move too."""
    broken = []
    for page in [*sorted((ROOT / "docs").rglob("*.md")), ROOT / "README.md"]:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
            path, _, anchor = target.partition("#")
            if re.match(r"[a-z]+:", target) or (path and not path.endswith(".md")):
                continue
            dest = (page.parent / path).resolve() if path else page
            generated = "." in anchor  # mkdocstrings' anchors (rlgrasp.envs.GraspEnv) are not headings
            if not dest.is_file() or (anchor and not generated and anchor not in _anchors(dest)):
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, "links that do not resolve:\n" + "\n".join(broken)


def test_the_newcomer_path_is_the_readme_as_written() -> None:
    """benchmarks/newcomer.py times the README's own commands: each one it runs is in the README
    verbatim, so the timed path and the page cannot drift apart."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("newcomer", ROOT / "benchmarks" / "newcomer.py")
    newcomer = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(newcomer)
    assert newcomer.missing_from_readme(newcomer.COMMANDS) == []
    assert newcomer.missing_from_readme(["python scripts/train.py experiment=nowhere"]) != []
