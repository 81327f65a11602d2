# examples/python/*.py and the tutorial's ```python blocks, run as a user runs them (from the repository's
# root, PYTHONPATH=build/python). Each example must finish without error and write what it says.
import os
import re
import subprocess
import sys

import pytest

from conftest import SOURCE_DIR

EXAMPLES = SOURCE_DIR / "examples" / "python"


def run(args, **kw):
    p = subprocess.run([sys.executable, *args], cwd=SOURCE_DIR, capture_output=True, text=True,
                       env=dict(os.environ, MPLBACKEND="Agg"), timeout=300, **kw)
    assert p.returncode == 0, p.stdout + p.stderr
    return p.stdout


def test_every_example_is_tested():
    tested = {"deform_and_certify.py", "plot_sigma3.py", "sigma3_explorer.py"}
    assert {p.name for p in EXAMPLES.glob("*.py")} == tested


def test_deform_and_certify(tmp_path):
    out = run([str(EXAMPLES / "deform_and_certify.py"), "--out", str(tmp_path / "bend")])
    assert "certified: True" in out
    assert (tmp_path / "bend" / "summary.json").exists() and (tmp_path / "bend" / "certificate.json").exists()


def test_deform_and_certify_with_a_mesh_file(tmp_path):
    # The ball's bare mesh: an automatic cage (cached), and a scenario of the beam cannot apply to it, so the
    # ball's own handles: its center held, a point pulled.
    scenario = tmp_path / "ball_pull.json"
    scenario.write_text('{"model": "%s", "handles": [{"source": [0, 0, 0], "target": [0, 0, 0]},'
                        ' {"source": [0.5, 0, 0], "target": [0.6, 0, 0]}]}'
                        % (SOURCE_DIR / "data" / "models" / "ball" / "mesh.obj"))
    out = run([str(EXAMPLES / "deform_and_certify.py"), "--model", str(SOURCE_DIR / "data" / "models" / "ball" / "mesh.obj"),
               "--scenario", str(scenario), "--out", str(tmp_path / "ball")])
    assert "certified: True" in out


def test_plot_sigma3(tmp_path):
    png = tmp_path / "sigma3.png"
    out = run([str(EXAMPLES / "plot_sigma3.py"), "--out", str(png)])
    assert png.stat().st_size > 10000, out
    assert re.search(r"min proven lower bound \d", out), out


def test_sigma3_explorer(tmp_path):
    png = tmp_path / "minima.png"
    out = run([str(EXAMPLES / "sigma3_explorer.py"), "--trials", "20", "--out", str(png)])
    assert re.search(r"^20 maps: \d+ with a strict interior minimum", out, re.M), out
    assert png.stat().st_size > 5000


def test_tutorial_python_blocks_run_in_order(tmp_path):
    text = (SOURCE_DIR / "docs" / "tutorial.md").read_text()
    blocks = re.findall(r"^```python\n(.*?)^```$", text, re.S | re.M)
    assert len(blocks) >= 5
    script = tmp_path / "tutorial.py"
    script.write_text("\n".join(blocks))
    out = run([str(script)])
    assert "\ncertified - min lower bound of sigma3" in "\n" + out, out
    assert "lambda_p2p: " in out
