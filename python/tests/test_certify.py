# lidef.certify: the verdict, the leaves as arrays, the files, and agreement with `lidef certify`.
import json
import subprocess

import numpy as np
import pytest

import lidef
from conftest import BEAM

PARAMS = {"samples": 3000}


def test_identity_is_certified_with_consistent_leaves(beam):
    cert = lidef.certify(beam, beam.identity(), **PARAMS)
    assert cert.certified and cert.reason == ""
    leaves = cert.leaves
    n = len(leaves["side"])
    assert n >= cert.voxels > 0
    assert leaves["center"].shape == (n, 3)
    for key in ("side", "sigma3", "lipschitz", "lower_bound", "depth", "certified"):
        assert leaves[key].shape == (n,), key
    assert leaves["certified"].all()
    # The certificate's bound is the smallest leaf bound; the identity has sigma3 = 1 everywhere.
    assert cert.min_lower_bound == pytest.approx(leaves["lower_bound"].min(), rel=1e-12)
    assert 0 < cert.min_lower_bound <= 1
    # (refined leaves are evaluated by a far-field expansion whose error the bound includes: ~1e-7 here)
    np.testing.assert_allclose(leaves["sigma3"], 1.0, atol=1e-6)


def test_global_injectivity_is_decided_with_the_local_certificate(beam):
    cert = lidef.certify(beam, beam.identity(), **PARAMS)
    assert cert.globally_injective is True
    assert cert.global_reason == ""
    assert cert.overlap_point is None


def test_a_mirrored_map_is_not_certified(beam):
    # x -> -x folds orientation everywhere: sigma3 = -1 at every voxel.
    Y = beam.identity().copy()
    Y[:, 0] *= -1
    cert = lidef.certify(beam, Y, **PARAMS)
    assert not cert.certified
    assert cert.reason
    assert cert.min_lower_bound < 0
    # Without a local certificate the global verdict is not decided.
    assert cert.globally_injective is None
    assert "local certificate" in cert.global_reason


def test_certificate_files_match_the_cli(beam, cli, tmp_path):
    # The same map through the Python module and through `lidef certify`: the same certificate (both call the
    # same library functions; certificate.json is deterministic).
    A = np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.1], [0.1, 0.0, 1.0]])
    Y = beam.identity().copy()
    nv = len(beam.cage_vertices)
    Y[:nv] = beam.cage_vertices @ A.T
    Y[nv:] = Y[nv:] @ A.T
    cert = lidef.certify(beam, Y, **PARAMS)
    cert.write(str(tmp_path / "py"))
    np.savetxt(tmp_path / "y.txt", Y, fmt="%.17g")
    subprocess.run([cli, "certify", str(BEAM), "--coeffs", str(tmp_path / "y.txt"), "--out", str(tmp_path / "cli"),
                    "--samples", "3000", "--grid", "0"], check=True, capture_output=True)
    py = json.loads((tmp_path / "py" / "certificate.json").read_text())
    ref = json.loads((tmp_path / "cli" / "certificate.json").read_text())
    for key in ("certified", "min_lower_bound", "voxels", "leaves", "coefficients_fnv1a64", "cage"):
        assert _find(py, key) == _find(ref, key), key
    assert (tmp_path / "py" / "voxels.csv").read_bytes() == (tmp_path / "cli" / "voxels.csv").read_bytes()
    assert (tmp_path / "py" / "leaves.vtu").exists()


def _find(obj, key):
    """The first value of `key` anywhere in a JSON object (the report nests its sections)."""
    if isinstance(obj, dict):
        if key in obj:
            return obj[key]
        for v in obj.values():
            found = _find(v, key)
            if found is not None:
                return found
    return None


def test_bad_coefficients_and_parameters_raise_input_error(beam):
    with pytest.raises(lidef.InputError, match=r"^Y: has 4 rows; a map of this cage has #V\+#F"):
        lidef.certify(beam, np.zeros((4, 3)))
    with pytest.raises(lidef.InputError, match="max_depth"):
        lidef.certify(beam, beam.identity(), max_depth=-3)
    with pytest.raises(lidef.InputError, match="no_such_parameter"):
        lidef.certify(beam, beam.identity(), no_such_parameter=1)
    with pytest.raises(lidef.InputError, match="bound"):
        lidef.certify(beam, beam.identity(), bound="fifth")


def test_distortion_bounds_hold_at_the_leaves_and_at_random_points(beam):
    # A map that stretches the beam: scale the coefficients' x column. The certificate's sigma1 and
    # sigma1/sigma3 bounds must not be below sigma1 and sigma1/sigma3 evaluated anywhere in the domain;
    # leaf centers and mesh vertices (on the domain's boundary) are such places.
    Y = beam.identity().copy()
    Y[:, 0] *= 1.5
    cert = lidef.certify(beam, Y, **PARAMS)
    assert cert.certified
    P = np.vstack([cert.leaves["center"], beam.mesh_vertices])
    _, J = beam.evaluate(Y, P)
    s = np.linalg.svd(J, compute_uv=False)
    sigma1, sigma3 = s[:, 0], s[:, 2]
    assert np.isfinite(cert.max_sigma1_upper_bound)
    assert np.isfinite(cert.max_distortion_upper_bound)
    assert cert.max_sigma1_upper_bound >= sigma1.max()
    assert cert.max_distortion_upper_bound >= (sigma1 / sigma3).max()
    # Not vacuous: within a factor of the sampled values (a stretch of 1.5 gives K near 1.5).
    assert cert.max_distortion_upper_bound < 2 * (sigma1 / sigma3).max()


def test_isometric_targets_are_proven_or_named(beam):
    # A stretch by 1.5 along x: sigma1 = 1.5 and sigma3 = 1 everywhere. A bound on sigma1 above 1.5 with room
    # is proven (distortion_met), one below 1.5 can never be and is named in the reason; the same for sigma3.
    Y = beam.identity().copy()
    Y[:, 0] *= 1.5
    free = lidef.certify(beam, Y, **PARAMS)
    assert free.certified and free.distortion_met is None
    met = lidef.certify(beam, Y, max_sigma1=1.6, min_sigma3=0.9, **PARAMS)
    assert met.certified, met.reason
    assert met.distortion_met is True
    assert met.max_sigma1_upper_bound <= 1.6 and met.min_lower_bound >= 0.9
    too_tight = lidef.certify(beam, Y, max_sigma1=1.4, **PARAMS)
    assert not too_tight.certified and too_tight.distortion_met is False
    assert "distortion bound sigma1 <= 1.4 not proven at" in too_tight.reason
    Y[:, 1] *= 0.8
    squeezed = lidef.certify(beam, Y, min_sigma3=0.85, **PARAMS)
    assert not squeezed.certified
    assert "distortion bound sigma3 >= 0.85 not proven at" in squeezed.reason
    with pytest.raises(lidef.InputError, match="max_sigma1"):
        lidef.certify(beam, Y, max_sigma1=0.5)
