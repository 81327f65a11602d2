# lidef.deform: the result's arrays, its certificate, its files and agreement with `lidef deform`.
import json
import subprocess
import threading
import time

import numpy as np
import pytest

import lidef
from conftest import BEAM, BEAM_BEND, SMALL


def test_bend_reaches_its_targets_with_a_certified_map(beam, bend, bend_result):
    r = bend_result
    assert r.certified and r.certificate.certified
    assert r.stop_reason in ("converged", "reached_not_converged")
    assert r.handles_reached and r.max_handle_error < 1e-3 * 2  # handle_tolerance x the beam's size (2)
    assert r.iterations > 0
    Y = r.coefficients
    assert Y.shape == beam.identity().shape
    # deformed_vertices are the mesh's vertices mapped by Y; the handles' images are at the targets.
    np.testing.assert_allclose(r.deformed_vertices, beam.evaluate(Y, beam.mesh_vertices)[0], atol=1e-9)
    f, J = beam.evaluate(Y, bend.sources)
    assert np.abs(f - bend.targets).max() == pytest.approx(r.max_handle_error, abs=1e-7)
    # Certified locally injective: det J > 0 wherever we look inside (here: at the mesh's vertices).
    assert (np.linalg.det(beam.evaluate(Y, beam.mesh_vertices)[1]) > 0).all()
    # certify() of the map with the solver's sampling parameters certifies it too, on the same leaves. Its bound
    # is close to the solver's but not equal: the solver certifies from its reduced coefficients, certify()
    # from the full ones (`lidef certify` on the CLI's coefficients.txt differs from its certificate.json the
    # same way); both are lower bounds.
    again = lidef.certify(beam, Y, samples=SMALL["samples"])
    assert again.certified
    assert len(again.leaves["side"]) == len(r.certificate.leaves["side"])
    assert again.min_lower_bound == pytest.approx(r.certificate.min_lower_bound, rel=1e-2)


def test_outputs_are_the_cli_files_and_the_same_map(bend_result, cli, tmp_path):
    # `lidef deform` with the same parameters computes the same map, digit for digit (one implementation).
    bend_result.write(str(tmp_path / "py"))
    scenario = json.loads(BEAM_BEND.read_text())
    scenario["parameters"] = SMALL
    (tmp_path / "bend.json").write_text(json.dumps(scenario))
    subprocess.run([cli, "deform", str(tmp_path / "bend.json"), "--models", str(BEAM.parent),
                    "--out", str(tmp_path / "cli"), "--quiet"], check=True, capture_output=True)
    names = sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert sorted(p.name for p in (tmp_path / "py").iterdir()) == names
    for name in ("coefficients.txt", "voxels.csv"):
        assert (tmp_path / "py" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes(), name

    def vertices(path):  # deformed.obj's header names the scenario; its vertices must agree
        return [l for l in path.read_text().splitlines() if l.startswith("v ")]

    assert vertices(tmp_path / "py" / "deformed.obj") == vertices(tmp_path / "cli" / "deformed.obj")
    py = json.loads((tmp_path / "py" / "summary.json").read_text())
    ref = json.loads((tmp_path / "cli" / "summary.json").read_text())
    for key in ("stop_reason", "iterations", "certified", "min_sigma3_lower_bound", "max_handle_error",
                "parameters", "global_volume_ratio"):
        assert py[key] == ref[key], key


def test_bad_input_names_the_argument(beam, bend):
    with pytest.raises(lidef.InputError, match="^targets: has 3 rows but sources has 10"):
        lidef.deform(beam, bend.sources, bend.targets[:3])
    outside = bend.sources.copy()
    outside[0] = [50.0, 0.0, 0.0]
    with pytest.raises(lidef.InputError, match="^sources: .*source"):
        lidef.deform(beam, outside, bend.targets, **SMALL)
    with pytest.raises(lidef.InputError, match="^lambda_p2p: "):
        lidef.deform(beam, bend.sources, bend.targets, lambda_p2p=-1.0)
    with pytest.raises(lidef.InputError, match="^reduced_dof: "):
        lidef.deform(beam, bend.sources, bend.targets, reduced_dof="many")
    with pytest.raises(lidef.InputError, match="lamda_p2p"):
        lidef.deform(beam, bend.sources, bend.targets, lamda_p2p=1.0)


def test_the_gil_is_released_while_deforming(beam, bend):
    # Another Python thread keeps running while deform() computes in this one.
    ticks = []
    done = threading.Event()

    def tick():
        while not done.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.005)

    t = threading.Thread(target=tick)
    t.start()
    start = time.monotonic()
    try:
        lidef.deform(beam, bend.sources, bend.targets, **SMALL)
    finally:
        done.set()
        t.join()
    elapsed = time.monotonic() - start
    during = [x for x in ticks if start < x < start + elapsed]
    # With the GIL held the thread would not tick at all during the call; released, it ticks every ~5 ms.
    assert len(during) > 0.2 * elapsed / 0.005, (len(during), elapsed)
