"""Every code block of the documentation pages is executed or marked as not.

The convention (docs pages, fenced blocks):

* ``python``: executed, page by page in order, in one fresh Python process per page (cwd a
  temporary folder, variant ``llvm_ad_rgb`` set, ``mitsuba as mi``, ``drjit as dr`` and
  ``mi_displace`` imported, the packaged scenes on Mitsuba's file resolver);
* ``xml``: a block that contains ``<scene`` is loaded with ``mi.load_string`` (in the same
  process, in page order); a fragment (one ``<shape>``, ``<bsdf>``, ...) is shown only;
* ``console`` (shell commands, command output) and ``text`` (anything else): shown only.

Any other language, a block without one and an indented code block fail, naming page and
line.  ``docs/plugins.md`` is generated and its examples are loaded by
``tests/test_plugin_reference.py``; the notebooks are run by ``tests/test_tutorials.py``.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from markdown_it import MarkdownIt

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
LANGUAGES = ("python", "xml", "console", "text")
#: MyST directives whose argument is the language of a code block.
CODE_DIRECTIVES = ("{code-block}", "{code}", "{sourcecode}", "{code-cell}")
#: MyST directives whose body is Markdown (code blocks inside them count).
MARKDOWN_DIRECTIVES = ("{note}", "{warning}", "{tip}", "{important}", "{attention}",
                       "{caution}", "{danger}", "{error}", "{hint}", "{seealso}",
                       "{admonition}", "{dropdown}")
#: Generated pages whose blocks another test checks; folders that are not pages.
CHECKED_ELSEWHERE = {"plugins.md"}
NOT_PAGES = ("figures", "atlas")
PAGE_TIMEOUT_S = 600


def pages() -> list[str]:
    """The Markdown pages of the site, relative to docs/ (as in docs/conf.py's exclusions)."""
    found = sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md"))
    return [p for p in found if p not in CHECKED_ELSEWHERE and p.split("/")[0] not in NOT_PAGES]


def code_blocks(text: str, first_line: int = 1) -> list[dict]:
    """The code blocks of a Markdown text: ``language`` ('' when none; 'indented' for an
    indented block), ``line`` (1-based line of the opening fence) and ``code``."""
    blocks = []
    for token in MarkdownIt("commonmark").parse(text):
        if token.type not in ("fence", "code_block"):
            continue
        line = first_line + token.map[0]
        if token.type == "code_block":
            blocks.append({"language": "indented", "line": line, "code": token.content})
            continue
        head, _, argument = token.info.strip().partition(" ")
        if head in CODE_DIRECTIVES:
            blocks.append({"language": argument.strip(), "line": line, "code": token.content})
        elif head in MARKDOWN_DIRECTIVES:
            blocks += code_blocks(token.content, line + 1)
        elif not head.startswith("{"):
            blocks.append({"language": head, "line": line, "code": token.content})
    return blocks


def executed(block: dict) -> bool:
    return block["language"] == "python" or (block["language"] == "xml" and "<scene" in block["code"])


#: Runs one page's blocks (JSON on stdin: page and blocks) in order; the code of each block is
#: compiled under the page's name and line, so a traceback points into the page.
RUNNER = r"""
import json, sys, traceback
import drjit as dr
import mitsuba as mi
import mi_displace
from mi_displace.core.resources import add_to_file_resolver

mi_displace.init("llvm_ad_rgb")
add_to_file_resolver()
job = json.load(sys.stdin)
namespace = {"__name__": "__main__", "mi": mi, "dr": dr, "mi_displace": mi_displace}
for block in job["blocks"]:
    where = f"{job['page']}:{block['line']}"
    try:
        if block["language"] == "python":
            source = "\n" * block["line"] + block["code"]
            exec(compile(source, job["page"], "exec"), namespace)
        else:
            mi.load_string(block["code"])
    except BaseException:
        print(f"FAILED {where} ({block['language']} block)\n{traceback.format_exc()}",
              file=sys.stderr)
        sys.exit(1)
    print(f"ran {where}")
"""


def _blocks(page: str) -> list[dict]:
    return code_blocks((DOCS / page).read_text())


@pytest.mark.parametrize("page", pages())
def test_every_block_is_executed_or_marked(page):
    wrong = [f"docs/{page}:{b['line']}: {b['language'] or 'no language'}" for b in _blocks(page)
             if b["language"] not in LANGUAGES]
    assert not wrong, ("code blocks must be python (executed), xml (a <scene> is loaded), "
                       "console or text (shown only):\n" + "\n".join(wrong))


@pytest.mark.parametrize("page", [p for p in pages() if any(map(executed, _blocks(p)))])
def test_page_code_runs(page, tmp_path):
    blocks = [b for b in _blocks(page) if executed(b)]
    env = {**os.environ, "MI_DISPLACE_VARIANT": "llvm_ad_rgb", "MPLBACKEND": "Agg"}
    run = subprocess.run([sys.executable, "-c", RUNNER], cwd=tmp_path, env=env, text=True,
                         input=json.dumps({"page": f"docs/{page}", "blocks": blocks}),
                         capture_output=True, timeout=PAGE_TIMEOUT_S)
    assert run.returncode == 0, run.stderr[-6000:]
    ran = [line for line in run.stdout.splitlines() if line.startswith("ran ")]
    assert len(ran) == len(blocks), run.stdout


def test_the_collector_sees_fences_directives_and_indented_blocks():
    """The parser finds what MyST renders as code: fences with their line, code directives,
    blocks inside admonitions, indented blocks; other directives are not code."""
    text = ("# T\n\n```python\nx = 1\n```\n\n```{toctree}\nindex\n```\n\n"
            "```{code-block} bash\nls\n```\n\n:::{note}\nx\n:::\n\n"
            "````{note}\n```sh\nls\n```\n````\n\n    indented\n")
    found = [(b["language"], b["line"]) for b in code_blocks(text)]
    assert found == [("python", 3), ("bash", 11), ("sh", 20), ("indented", 25)]
