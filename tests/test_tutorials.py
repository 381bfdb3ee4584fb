"""The tutorials in docs/tutorials run: each notebook is executed top to bottom in a fresh
Python kernel (nbclient, as ``pytest --nbmake docs/tutorials`` does), for every test
variant, and its own closing asserts (finite images, a falling loss, ...) must hold.
They are committed without outputs and the index names each one."""
import json
import os
import re
import time
from pathlib import Path

import nbclient
import nbformat
import pytest

TUTORIALS_DIR = Path(__file__).resolve().parents[1] / "docs" / "tutorials"
TUTORIALS = ["01_first_displacement", "02_choosing_a_technique", "03_baking", "04_volumes",
             "05_differentiable"]
CELL_TIMEOUT_S = 600   # per cell; each notebook takes well under a minute on a 2-core CPU


def _notebook(name: str) -> dict:
    return json.loads((TUTORIALS_DIR / f"{name}.ipynb").read_text())


def test_every_notebook_is_listed_and_committed_without_outputs():
    assert sorted(p.stem for p in TUTORIALS_DIR.glob("*.ipynb")) == TUTORIALS
    index = (TUTORIALS_DIR / "README.md").read_text()
    for name in TUTORIALS:
        assert f"({name}.ipynb)" in index, f"docs/tutorials/README.md does not link {name}"
        cells = _notebook(name)["cells"]
        assert cells[0]["cell_type"] == "markdown", f"{name}: no introduction"
        for cell in cells:
            if cell["cell_type"] == "code":
                assert not cell["outputs"] and cell["execution_count"] is None, (
                    f"{name}: clear the outputs before committing")


@pytest.mark.parametrize("name", TUTORIALS)
def test_notebook_links_to_guides_that_exist(name):
    intro = "".join(_notebook(name)["cells"][0]["source"])
    links = re.findall(r"\]\((\.\./[^)#]+\.md)\)", intro)
    assert links, f"{name}: the introduction names no guide"
    for link in links:
        assert (TUTORIALS_DIR / link).resolve().is_file(), f"{name}: {link} does not exist"


@pytest.mark.parametrize("name", TUTORIALS)
def test_notebook_runs(variant, name, tmp_path):
    nb = nbformat.read(TUTORIALS_DIR / f"{name}.ipynb", as_version=4)
    client = nbclient.NotebookClient(nb, timeout=CELL_TIMEOUT_S, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    # figures inline, as in Jupyter, whatever backend the suite's environment chose
    env = {**os.environ, "MI_DISPLACE_VARIANT": variant,
           "MPLBACKEND": "module://matplotlib_inline.backend_inline"}
    start = time.perf_counter()
    client.execute(env=env)
    print(f"{name} ({variant}): {time.perf_counter() - start:.1f} s")
    images = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
              if "image/png" in o.get("data", {})]
    assert images, f"{name}: no figure was drawn"
