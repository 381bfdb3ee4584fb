"""The documentation site builds: Sphinx (docs/conf.py) with warnings as errors and every
cross reference checked, as ``scripts/docs.sh`` runs it; every page named in a toctree has
its HTML page, and every image and local link of the output resolves to a file."""
from __future__ import annotations

import importlib.util
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest
from markdown_it import MarkdownIt

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
BUILD_TIMEOUT_S = 600


def toctree_entries(page: str) -> list[str]:
    """The documents a page's ``{toctree}`` blocks name, relative to docs/ (no suffix)."""
    folder = Path(page).parent
    entries = []
    for token in MarkdownIt("commonmark").parse((DOCS / page).read_text()):
        if token.type == "fence" and token.info.strip() == "{toctree}":
            for line in token.content.splitlines():
                line = line.strip()
                if line and not line.startswith(":"):
                    entries.append((folder / line).as_posix())
    return entries


def toctree_pages() -> list[str]:
    """Every document reachable from index through the toctrees, index first."""
    found, todo = [], ["index"]
    while todo:
        name = todo.pop(0)
        if name in found:
            continue
        found.append(name)
        source = DOCS / f"{name}.md"
        if source.is_file():
            todo += toctree_entries(f"{name}.md")
    return found


class _Links(HTMLParser):
    """The ``src`` of each ``<img>`` and the ``href`` of each ``<a>`` of one HTML page."""

    def __init__(self):
        super().__init__()
        self.images, self.links = [], []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img" and attrs.get("src"):
            self.images.append(attrs["src"])
        elif tag == "a" and attrs.get("href"):
            self.links.append(attrs["href"])


def _local_target(html: Path, url: str) -> Path | None:
    """The file a relative URL of ``html`` points to; None for data:, external and
    same-page URLs."""
    parts = urlsplit(url)
    if parts.scheme or parts.netloc or not parts.path:
        return None
    return (html.parent / unquote(parts.path)).resolve()


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    assert importlib.util.find_spec("myst_nb"), "the docs extra is missing: pip install -e '.[docs]'"
    out = tmp_path_factory.mktemp("site")
    start = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-n", "-q",
                          "-b", "html", str(DOCS), str(out)], cwd=ROOT, capture_output=True,
                         text=True, timeout=BUILD_TIMEOUT_S)
    print(f"sphinx-build: {time.perf_counter() - start:.1f} s")
    assert run.returncode == 0, f"the docs build failed or warned:\n{run.stderr[-8000:]}"
    return out


def test_every_toctree_page_is_built(site):
    pages = toctree_pages()
    # the site's sections: guides, reference, tutorials, API
    for name in ("plugins", "displaced", "tradeoff", "changelog", "api/index",
                 "tutorials/01_first_displacement"):
        assert name in pages, f"{name} is in no toctree reachable from docs/index.md"
    missing = [name for name in pages if not (site / f"{name}.html").is_file()]
    assert not missing, f"pages in a toctree without HTML: {missing}"


def test_every_image_and_local_link_resolves(site):
    pages = sorted(site.rglob("*.html"))
    assert len(pages) >= len(toctree_pages())
    broken, images = [], 0
    for html in pages:
        parser = _Links()
        parser.feed(html.read_text(encoding="utf-8"))
        for kind, urls in (("img", parser.images), ("a", parser.links)):
            for url in urls:
                target = _local_target(html, url)
                if target is None:
                    continue
                images += kind == "img"
                if not target.is_file():
                    broken.append(f"{html.relative_to(site)}: <{kind}> {url}")
    assert images > 0, "no local image in the output: the figures were not copied"
    assert not broken, "\n".join(broken)
