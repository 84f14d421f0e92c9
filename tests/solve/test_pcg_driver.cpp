// The PCG driver (solve/pcg.cpp) over devices that differ in how they report: one that cannot read
// the set-up's scalars before the first iterations (Device::pcgSetupReadable false) and launches
// them in chunks of checkEvery (pcgOneLaunch false) must get the same answer, iteration count and
// convergence as the device it wraps. The driver once stopped such a device after its first chunk
// and reported the cap.
#include "backends/reference/reference_device.hpp"
#include "common/device_fakes.hpp"
#include "common/test_problems.hpp"
#include "solve/pcg.hpp"

#include <gtest/gtest.h>

namespace corofem::test {
namespace {

class NoSetupRead final : public ForwardingDevice {
 public:
  explicit NoSetupRead(detail::Device& inner) : ForwardingDevice(inner) {}
  bool pcgSetupReadable() const override { return false; }
  bool pcgOneLaunch() const override { return false; }
};

TEST(PcgDriver, ADeviceWithoutTheSetUpReadIteratesChunkByChunkToTheSameAnswer) {
  detail::Problem p = makeProblem(cellBox(6, 2, 2, 0.1, 0.1, 0.1), 1e5, 0.3, 1000.0);
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (p.mesh.nodes[3 * n] < 1e-9)
      for (int k = 0; k < 3; ++k) p.constrained[3 * n + k] = 1;
  SolverDesc s;
  s.preconditioner = PreconditionerKind::Diagonal;
  s.tolerance = 1e-9;
  s.maxIterations = 500;
  s.checkEvery = 3;  // many chunks
  const std::unique_ptr<detail::Device> ref = detail::createReferenceDevice({&p}, s);
  const Eigen::VectorXd x0 = p.restPositions;
  ref->setPositions({0}, {&x0});
  const Eigen::VectorXd b = randomVector(p.dofCount(), 11);
  auto solve = [&](detail::Device& d, Eigen::VectorXd& x) {
    x = Eigen::VectorXd::Zero(b.size());
    std::vector<detail::PcgSolve> solves(1);
    solves[0].coeffs = {3600.0, 0.0, 1.0};
    solves[0].b = &b;
    solves[0].x = &x;
    detail::solvePcg(d, {0}, solves, s);
    EXPECT_TRUE(solves[0].failure.empty()) << solves[0].failure;
    return solves[0].stats;
  };
  Eigen::VectorXd xRef, xWrapped;
  const detail::LinearSolveStats want = solve(*ref, xRef);
  NoSetupRead wrapped(*ref);
  const detail::LinearSolveStats got = solve(wrapped, xWrapped);
  ASSERT_TRUE(want.converged);
  EXPECT_GT(want.iterations, 3 * s.checkEvery) << "the solve must take several chunks";
  EXPECT_TRUE(got.converged);
  EXPECT_EQ(got.iterations, want.iterations);
  EXPECT_EQ(got.relativeResidual, want.relativeResidual);
  EXPECT_TRUE(sameBits(xWrapped, xRef));
}

}  // namespace
}  // namespace corofem::test
