# lidef.load_model, Model's arrays, identity() and evaluate().
import numpy as np
import pytest

import lidef
from conftest import BEAM, SOURCE_DIR


def test_model_arrays_have_the_documented_shapes_and_types(beam):
    for V, F in ((beam.cage_vertices, beam.cage_faces), (beam.mesh_vertices, beam.mesh_faces)):
        assert V.dtype == np.float64 and V.ndim == 2 and V.shape[1] == 3
        assert F.dtype == np.int32 and F.ndim == 2 and F.shape[1] == 3
        assert F.min() == 0 and F.max() == len(V) - 1
    # beam/cage.obj's vertex lines, in file order.
    lines = [l.split() for l in open(BEAM / "cage.obj") if l.startswith("v ")]
    np.testing.assert_array_equal(beam.cage_vertices, np.array([[float(x) for x in l[1:4]] for l in lines]))


def test_identity_maps_every_point_to_itself_with_jacobian_one(beam):
    Y = beam.identity()
    assert Y.shape == (len(beam.cage_vertices) + len(beam.cage_faces), 3)
    P = beam.mesh_vertices[::97]
    f, J = beam.evaluate(Y, P)
    assert f.shape == P.shape and J.shape == (len(P), 3, 3)
    np.testing.assert_allclose(f, P, atol=1e-9)
    np.testing.assert_allclose(J, np.broadcast_to(np.eye(3), J.shape), atol=1e-9)


def test_jacobian_is_df_a_dp_b(beam):
    # The affine map p -> A p has the coefficients y_v = A v (vertex rows) and y_t = A n_t, its normal
    # derivative on face t (face rows; the identity's are n_t); J[i, a, b] must be A[a, b], not its transpose.
    A = np.array([[1.0, 0.3, 0.0], [0.0, 1.2, 0.1], [0.2, 0.0, 0.9]])
    Y = beam.identity().copy()
    nv = len(beam.cage_vertices)
    Y[:nv] = beam.cage_vertices @ A.T
    Y[nv:] = Y[nv:] @ A.T
    P = beam.mesh_vertices[::211]
    f, J = beam.evaluate(Y, P)
    np.testing.assert_allclose(f, P @ A.T, atol=1e-8)
    np.testing.assert_allclose(J, np.broadcast_to(A, J.shape), atol=1e-8)


def test_bad_input_raises_input_error_naming_it(beam, tmp_path):
    assert issubclass(lidef.InputError, ValueError)
    with pytest.raises(lidef.InputError, match="no_such_model"):
        lidef.load_model(str(tmp_path / "no_such_model"))
    with pytest.raises(lidef.InputError, match="^Y: "):
        beam.evaluate(np.zeros((5, 3)), beam.mesh_vertices[:2])
    with pytest.raises(lidef.InputError, match="^P: .*shape"):
        beam.evaluate(beam.identity(), np.zeros((4, 2)))
    bad = beam.mesh_vertices[:3].copy()
    bad[1, 2] = np.nan
    with pytest.raises(lidef.InputError, match="^P: row 1 holds a non-finite number"):
        beam.evaluate(beam.identity(), bad)
    with pytest.raises(lidef.InputError, match="^P: "):
        beam.evaluate(beam.identity(), "not an array")


def test_a_mesh_file_gets_an_automatic_cage(tmp_path):
    # A mesh file stands for a model: its automatic cage (made once, cached in LIDEF_CACHE_DIR).
    model = lidef.load_model(str(SOURCE_DIR / "data" / "models" / "ball" / "mesh.obj"))
    assert len(model.cage_faces) > 0
    ball_mesh = [l for l in open(SOURCE_DIR / "data" / "models" / "ball" / "mesh.obj") if l.startswith("v ")]
    assert model.mesh_vertices.shape == (len(ball_mesh), 3)
    f, _ = model.evaluate(model.identity(), model.mesh_vertices[:10])
    np.testing.assert_allclose(f, model.mesh_vertices[:10], atol=1e-8)
