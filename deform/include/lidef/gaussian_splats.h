// 3D Gaussian splats (the PLY layout of 3D Gaussian Splatting: x y z, nx ny nz, f_dc_0..2, f_rest_0..44,
// opacity, scale_0..2, rot_0..3) and their image under a map f with Jacobian J.
//
// A splat is a Gaussian with mean μ = (x, y, z) and covariance Σ = R diag(s)² Rᵀ, s = exp(scale_k) (log
// scales) and R the rotation of the quaternion (rot_0, rot_1, rot_2, rot_3) = (w, x, y, z), normalized. Its
// image under f, to first order at μ, is the Gaussian with mean f(μ) and covariance J Σ Jᵀ (exactly: a linear
// map of a Gaussian). New scales and quaternion come from the eigen-decomposition J Σ Jᵀ = U diag(λ) Uᵀ:
// scale_k = ½ log λ_k with λ in ascending order, U's columns signed so that det U = +1, the quaternion of U
// with w ≥ 0. The view-dependent colour (f_rest, real spherical harmonics of degrees 1..3, 15 coefficients
// per colour channel stored channel after channel: f_rest[c·15 + k]) is rotated by the rotation Q of J's
// polar decomposition J = Q P: the colour seen along d after the map is the colour seen along Qᵀd before it.
// f_dc, opacity and every other property are kept as they are.
#pragma once
#include <string>
#include <vector>

#include "lidef/point_cloud_io.h"
#include "lidef/types.h"

namespace lidef {

// Whether a PLY cloud's vertex element is a splat layout (scale_0 and rot_0 present).
bool is_gaussian_splat_cloud(const PlyCloud& cloud);

// Reads a splat PLY: read_ply_cloud, then checks that scale_0..2 and rot_0..3 exist (InputError naming the
// file and the missing property, e.g. "splat PLY without scales") and that every quaternion is finite and
// non-zero and every scale finite.
PlyCloud read_gaussian_splats(const std::string& path);

// Σ = R(q) diag(exp(scale))² R(q)ᵀ. q = (w, x, y, z), any non-zero length.
Mat3 splat_covariance(const Vec3& log_scale, const Eigen::Vector4d& q_wxyz);

// Scales (log) and quaternion (w, x, y, z; unit, w ≥ 0) of a symmetric positive definite Σ, with the
// convention above; splat_covariance of the result gives back Σ up to rounding.
void splat_scale_rotation(const Mat3& sigma, Vec3* log_scale, Eigen::Vector4d* q_wxyz);

// The real spherical-harmonic basis of 3D Gaussian Splatting, degrees 1..3 (15 values, its order and
// constants) at the unit direction d.
Eigen::Matrix<double, 15, 1> sh_basis_degree1to3(const Vec3& d);

// The 15 by 15 block-diagonal matrix M (blocks 3, 5, 7) with Y(Rᵀd) = M Y(d) for every d (Y =
// sh_basis_degree1to3): fitted per band by least squares on fixed sample directions, exact up to rounding
// because each band's span is invariant under rotation. Coefficients c of a colour are rotated by R as Mᵀc.
Eigen::Matrix<double, 15, 15> sh_rotation(const Mat3& R);

// The rotation Q of the polar decomposition J = Q P (P symmetric positive semi-definite), for det J > 0.
Mat3 polar_rotation(const Mat3& J);

// Maps the splats of `cloud` in place: positions ← mapped (#P by 3, f(μ_i)); scales, rotations ← from
// J_i Σ_i J_iᵀ; f_rest (when present) rotated by J_i's polar rotation; normals nx ny nz (when present) mapped
// by the cofactor matrix and normalized. JT: 3#P by 3, rows 3i..3i+2 = J(μ_i)ᵀ (mesh_fields.h's layout).
// Throws InputError when a J has det ≤ 0 (a certified map never has one at a covered point).
void map_gaussian_splats(PlyCloud& cloud, const MatX3d& mapped, const MatXd& JT);

}  // namespace lidef
