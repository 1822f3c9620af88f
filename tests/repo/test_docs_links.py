"""Every relative link in the README and docs/ points at a file of the repository, and every
#anchor at a heading of it: sections move between pages, and a link left behind would send
a reader nowhere."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LINK = re.compile(r"\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def prose(path: Path) -> str:
    """The page without its code blocks (a ``# comment`` there is no heading, nor a link)."""
    return re.sub(r"```.*?```", "", path.read_text(), flags=re.S)


def anchors(path: Path) -> set[str]:
    return {slug(m.group(1)) for m in re.finditer(r"^#+ (.+)$", prose(path), re.M)}


def links(path: Path):
    for target in LINK.findall(prose(path)):
        if not re.match(r"[a-z]+:", target):
            yield target


def test_slug_follows_githubs_rule():
    assert slug("The bank's 8-car scenes: every row, and more") == "the-banks-8-car-scenes-every-row-and-more"
    assert slug("`trustfg sim`") == "trustfg-sim"


def test_every_relative_link_and_anchor_resolves():
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    broken = []
    for page in pages:
        for target in links(page):
            file, _, anchor = target.partition("#")
            dest = (page.parent / file).resolve() if file else page
            if not dest.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such heading)")
    assert not broken, "\n".join(broken)
