// Where a dynamics step's vectors live, and the per-dof passes of the dynamics driver over them
// (solve/dynamics.cpp). The driver keeps every decision (Newton's stop, the blow-up and runaway
// guards, substeps, the commit) and reads only scalars from the passes; the store keeps the
// vectors and runs the passes and the device calls on them. HostStepStore keeps them on the host,
// in double, and serves every device. A device that keeps them itself (Device::createStepStore:
// the Vulkan device's, backends/vulkan/vulkan_step_store.hpp) implements the same passes on its own
// buffers, so that a step's vectors need not cross to the host: the driver is written once over
// either.
//
// Per body the store holds four states (StateSlot), each the five vectors of a dynamics state
// (StateVec, 3N reals in the problem's numbering): the committed one, the step's start (kept for
// the retries of a substepped step), the state before the last step (rollback), and the step's
// result, which a commit swaps in. Swaps and copies of whole states are the store's, so that a
// device swaps buffers and never moves a vector through the host.
#pragma once

#include "device/device.hpp"
#include "solve/driver.hpp"
#include "solve/pcg.hpp"

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <memory>
#include <vector>

namespace corofem::detail {

class DeviceSlot;

/// The states a store keeps per body.
enum class StateSlot : unsigned { Committed, Start, Previous, Result, kCount };
/// The vectors of a state: x, v, a at its time, f_ext there (the loads, the application's forces
/// and the springs' pull on free dofs) and the supports' reactions (the constrained rows of the
/// residual).
enum class StateVec : unsigned { X, V, A, Fext, Reaction, kCount };
/// The step's other vectors: the scheme's vb and xb, the constrained dofs' targets, f_int, C v, the
/// residual r, Newton's correction dv and its right-hand side -r / ka.
enum class Scratch : unsigned { Vb, Xb, Target, Fint, Cv, R, Dv, Rhs, kCount };

/// The scheme's affine maps of one advance (DynamicsDriver): a(v) = ka (v - vb), x(v) = xb + kx v,
/// with vb = v_n + cv a_n and xb = x_n + h v_n + ca a_n - kx vb for Newmark, vb = v_n and xb = x_n
/// for backward Euler.
struct SchemeMaps {
  bool newmark = false;
  double h = 0.0, ka = 0.0, kx = 0.0, cv = 0.0, ca = 0.0;
};

/// One body's part of StepStore::begin.
struct BeginArgs {
  SchemeMaps maps;
  double t1 = 0.0;        ///< the advance's end time (s): the loads' and prescribed targets' time
  double fraction = 1.0;  ///< how far through the whole step t1 is: held targets are reached in proportion
  /// The state the held targets start from: the step's start (Start, after a substep committed) or
  /// the committed state (Committed, the step's first advance).
  StateSlot from = StateSlot::Committed;
};

/// The sums of StepStore::residual over a body's free dofs: |M a|^2, |C v|^2, |f_int|^2,
/// |S (x - t)|^2, |r|^2, the non-finite entries of x, v and a (all dofs), and |f_ext|^2.
struct ResidualSums {
  double ma = 0.0, cv = 0.0, fint = 0.0, spring = 0.0, r = 0.0;
  double nonFinite = 0.0;
  double fext = 0.0;
};

/// The sums of StepStore::end over dx = x_{n+1} - x_n (Result.X - Committed.X), R the reactions and
/// F f_ext of the two states: (R_n + R).dx, (F_n + F).dx, R_n.dx, R.dx, F_n.dx, F.dx, and m v^2.
using EndSums = std::array<double, 7>;

class StepStore {
 public:
  virtual ~StepStore() = default;

  // -- the bodies' vectors

  /// A state's vector of the body, as the store holds it (a device's store reads it back first).
  /// Valid until the next call that changes that state.
  virtual const Eigen::VectorXd& state(std::size_t body, StateSlot slot, StateVec vec) = 0;
  /// Replaces a state's vector (3N entries).
  virtual void setState(std::size_t body, StateSlot slot, StateVec vec, const Eigen::VectorXd& value) = 0;
  /// Sets a state's vector to 3N zeros, with no vector from the caller (a device's store clears its
  /// own buffer; the host's reuses the vector's storage).
  virtual void setZero(std::size_t body, StateSlot slot, StateVec vec) = 0;
  /// A scratch vector as the last pass left it.
  virtual const Eigen::VectorXd& scratch(std::size_t body, Scratch vec) = 0;
  /// Exchanges two states of the body (all five vectors), or copies one onto another.
  virtual void swap(std::size_t body, StateSlot a, StateSlot b) = 0;
  virtual void copy(std::size_t body, StateSlot from, StateSlot to) = 0;
  /// The body's problem changed (its constrained dofs, loads or springs): the store reads it again
  /// (the host's reads the loads and springs at each pass, and its free dofs here).
  virtual void problemChanged(std::size_t body) = 0;
  /// What the application holds the body by (DynamicsDriver::setControls); empty vectors: none.
  virtual void setControls(std::size_t body, const BodyControls& controls) = 0;
  virtual const BodyControls& controls(std::size_t body) const = 0;
  /// The body goes; later bodies' indices move down by one.
  virtual void removeBody(std::size_t body) = 0;
  /// 1 on the body's free dofs, 0 on constrained ones.
  virtual const Eigen::ArrayXd& freeMask(std::size_t body) const = 0;

  // -- the device's calls on the store's vectors (through the slot, with its failover)

  /// The device's positions of `set` from each body's state `slot` (its X).
  virtual void setPositions(DeviceSlot& device, const BodySet& set, StateSlot slot) = 0;
  /// f_int at the device's positions into Fint.
  virtual void internalForces(DeviceSlot& device, const BodySet& set) = 0;
  /// The damping force C v of each body's state `slot` (its V) into Cv: the mass part alone (beta
  /// = 0) as a scaling of the lumped mass, the stiffness part by the device's product. Bodies
  /// without damping get Cv = 0.
  virtual void damping(DeviceSlot& device, const BodySet& set, StateSlot slot) = 0;
  /// The linear solves A Dv = Rhs of `set` from Dv = 0, with solves[i].coeffs; fills the solves'
  /// stats and failures (their b and x are the store's).
  virtual void solve(DeviceSlot& device, const BodySet& set, std::vector<PcgSolve>& solves) = 0;

  // -- the driver's per-dof passes, each over a body's dofs with its sums in dof order (a body's
  // bits do not depend on the set it is in, nor on the host's threads)

  /// From each body's committed state: Vb, Xb, the targets of the constrained dofs at t1 into
  /// Target (the scene's fixed and prescribed targets, the application's held ones where given),
  /// f_ext(t1) into Result.Fext (the loads and the application's forces), Newton's starting v into
  /// Result.V (v_n; a constrained dof the v that lands it on its target), Cv = 0. It returns
  /// nothing, so that a device's store need not wait for it.
  virtual void begin(const BodySet& set, const std::vector<BeginArgs>& args) = 0;
  /// Result.X = Xb + kx Result.V and Result.A = ka (Result.V - Vb).
  virtual void positions(const BodySet& set, const std::vector<SchemeMaps>& maps) = 0;
  /// r = M a + C v + f_int + S (x - t) - f_ext at the result state into R, Rhs = -r / ka, and the
  /// sums of ResidualSums.
  virtual void residual(const BodySet& set, const std::vector<SchemeMaps>& maps, std::vector<ResidualSums>& sums) = 0;
  /// Result.V += Dv; returns the non-finite entries of Dv per body.
  virtual void update(const BodySet& set, std::vector<double>& nonFinite) = 0;
  /// The step's end at the result state: its reactions (the constrained rows of R) into
  /// Result.Reaction, the springs' pull on free dofs added to Result.Fext, and the sums of EndSums.
  virtual void end(const BodySet& set, std::vector<EndSums>& sums) = 0;
};

/// The damping force C v of each body of `set` (problems[k], v[k]) into cv[k] (StepStore::damping):
/// 0 without damping, the scaling of the lumped mass for mass damping alone (beta = 0), else the
/// device's product with C = alpha M + beta K.
void dampingForces(DeviceSlot& device, const BodySet& set, const std::vector<const Problem*>& problems,
                   const ConstVectors& v, const Vectors& cv);

/// The store on the host (double, the problem's numbering); the slot's problems outlive it.
std::unique_ptr<StepStore> createHostStepStore(const DeviceSlot& slot);

}  // namespace corofem::detail
