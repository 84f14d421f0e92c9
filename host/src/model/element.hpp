// Linear tetrahedron: rest-state set-up (paper Eqs. 4-8), deformation gradient, rotation, forces.
// Double precision, Eigen. This is the mathematics every backend reproduces.
#pragma once

#include <corofem/scene.hpp>

#include <Eigen/Core>

#include <array>

namespace corofem::detail {

using Mat3 = Eigen::Matrix3d;
using Vec3d = Eigen::Vector3d;
using Mat12 = Eigen::Matrix<double, 12, 12>;
using Vec12 = Eigen::Matrix<double, 12, 1>;
using Grad43 = Eigen::Matrix<double, 4, 3>;  ///< row i = gradient of shape function N_i (1/m)

/// Rest state of one element, computed once.
struct ElementRest {
  Mat3 DmInv;       ///< inverse of the rest edge matrix [X1-X0, X2-X0, X3-X0] (columns)
  Grad43 grad;      ///< shape-function gradients; sum of rows is zero
  double volume = 0;///< rest volume (m^3), > 0 for a positively oriented element
};

/// Lame parameters from E and nu. Throws Error(BadInput) unless E > 0 and -1 < nu < 0.5.
struct Lame { double lambda = 0, mu = 0; };
Lame lameFromYoungPoisson(double youngsModulus, double poissonRatio);

/// Rest set-up from the 4 rest node positions. Throws Error(BadInput) when the volume is not > 0.
ElementRest computeElementRest(const std::array<Vec3d, 4>& X);

/// K_e = V B^T H B (12x12, node-major dofs: node i, component c at 3i+c).
Mat12 linearStiffness(const ElementRest& rest, const Lame& lame);

/// F = D_s D_m^-1 from current positions.
Mat3 deformationGradient(const ElementRest& rest, const std::array<Vec3d, 4>& x);

/// Rotational part of F by polar decomposition F = R S, det R = +1 (the reference): Higham's
/// scaled Newton iteration where det F > 1e-6 |F|_F^3, else the SVD, with the smallest singular
/// direction flipped for inverted elements. Both give U V^T of F's SVD to rounding where both run.
Mat3 polarRotation(const Mat3& F);

/// Co-rotational element force f = R K (R^T x - X) (Eq. 9), 12 entries; where `energy` is given,
/// the element's strain energy 1/2 u^T K u too, u = R^T x - X (the bits of corotationalEnergy).
Vec12 corotationalForce(const Mat12& K, const Mat3& R, const std::array<Vec3d, 4>& x,
                        const std::array<Vec3d, 4>& X, double* energy = nullptr);

// ---- additions (model helper): volume, mass, energy, rotated stiffness, small-strain stress ----

/// Signed volume (X1-X0).((X2-X0)x(X3-X0)) / 6 (m^3); > 0 for a positively oriented element.
double signedVolume(const std::array<Vec3d, 4>& X);

/// Lumped mass of each of the element's 4 nodes: rho V / 4 (kg), per component.
double lumpedNodeMass(const ElementRest& rest, double density);

/// Consistent mass of the linear tetrahedron: M_(3i+c)(3j+c) = rho V / 20 (1 + delta_ij), zero
/// between different components (12x12, node-major). Its row sums equal the lumped masses.
Mat12 consistentMass(const ElementRest& rest, double density);

/// R K R^T applied block-wise (paper Eq. 11): the co-rotational element tangent, symmetric but for
/// the rounding of its diagonal blocks. K must be symmetric: the blocks below the diagonal are
/// taken as the transposes of those above it.
Mat12 rotateStiffness(const Mat12& K, const Mat3& R);

/// Strain energy 1/2 u^T K u with u = R^T x - X (co-rotational; R = I gives the linear energy) (J).
double corotationalEnergy(const Mat12& K, const Mat3& R, const std::array<Vec3d, 4>& x,
                          const std::array<Vec3d, 4>& X);

/// Small strain eps = (F + F^T)/2 - I of a deformation gradient (for the linear formulation; for the
/// co-rotational one pass R^T F).
Mat3 smallStrain(const Mat3& F);

/// Hooke's law sigma = lambda tr(eps) I + 2 mu eps (Pa). Equals H B u in tensor form (Eq. 8).
Mat3 hookeStress(const Mat3& strain, const Lame& lame);

}  // namespace corofem::detail
