"""Every notebook in notebooks/ runs top to bottom against the installed package.

The code cells are executed in one namespace with matplotlib's Agg backend, the way a
reader would run them; a cell that raises fails the test with the notebook and cell.
"""
import json
import pathlib

import pytest

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")

NOTEBOOKS = sorted((pathlib.Path(__file__).resolve().parents[2] / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs(path):
    import matplotlib.pyplot as plt

    nb = json.loads(path.read_text())
    namespace = {"__name__": "__notebook__"}
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] != "code":
            continue
        source = "".join(cell["source"])
        try:
            exec(compile(source, f"{path.name}[cell {i}]", "exec"), namespace)
        except Exception as e:  # pragma: no cover - the message is the point
            raise AssertionError(f"{path.name} cell {i} failed: {e!r}\n{source}") from e
    plt.close("all")


def test_notebooks_exist():
    assert NOTEBOOKS, "notebooks/ has no notebook to run"
