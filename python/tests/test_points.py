# Point clouds as models: a binary PLY of points (no faces) gets an automatic cage, deforms to a certified map
# whose mapped points are the map evaluated at them, and bad clouds raise lidef.InputError naming the file.
import numpy as np
import pytest

import lidef
from conftest import SMALL


def write_ply_points(path, P, normals=None):
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else [])
    data = P if normals is None else np.hstack([P, normals])
    header = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(P)
    header += "".join("property float %s\n" % p for p in props) + "end_header\n"
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.ascontiguousarray(data, dtype="<f4").tobytes())


@pytest.fixture(scope="module")
def cloud(beam, tmp_path_factory):
    P = beam.mesh_vertices[::3].astype(np.float32).astype(np.float64)  # the float values the file holds
    path = tmp_path_factory.mktemp("cloud") / "points.ply"
    write_ply_points(path, P)
    return P, lidef.load_model(str(path))


def test_a_point_cloud_loads_with_its_points_and_no_faces(cloud):
    P, m = cloud
    assert m.mesh_faces.shape == (0, 3)
    np.testing.assert_array_equal(m.mesh_vertices, P)
    assert len(m.cage_vertices) >= 4 and m.cage_faces.shape[1] == 3


def test_a_point_cloud_deforms_certified_and_its_points_follow_the_map(cloud):
    P, m = cloud
    lo, hi = P[:, 0].argmin(), P[:, 0].argmax()
    sources = P[[lo, hi]]
    targets = sources.copy()
    targets[1, 2] += 0.1 * (P[:, 0].max() - P[:, 0].min())
    r = lidef.deform(m, sources, targets, **SMALL)
    assert r.certified
    f, _ = m.evaluate(r.coefficients, P)
    np.testing.assert_allclose(r.deformed_vertices, f, atol=1e-9)
    # No surface: nothing to compare for global injectivity, and the reason says so.
    assert r.certificate.globally_injective is None
    assert "point cloud" in r.certificate.global_reason


def test_bad_clouds_raise_input_error_naming_the_file(tmp_path):
    bad = tmp_path / "nan.ply"
    P = np.zeros((5, 3))
    P[2, 1] = np.nan
    write_ply_points(bad, P)
    with pytest.raises(lidef.InputError, match="nan.ply"):
        lidef.load_model(str(bad))
    empty = tmp_path / "empty.ply"
    write_ply_points(empty, np.zeros((0, 3)))
    with pytest.raises(lidef.InputError, match="empty.ply"):
        lidef.load_model(str(empty))
