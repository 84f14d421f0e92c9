// The Vulkan device's step store (vulkan_step_store.hpp) over kernels/vulkan/step.comp.
#include "backends/vulkan/vulkan_step_store.hpp"

#include "backends/vulkan/shaders.hpp"
#include "backends/vulkan/vk_runtime.hpp"
#include "backends/vulkan/vulkan_device_impl.hpp"
#include "solve/body_scale.hpp"
#include "solve/device_slot.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>

namespace corofem::detail {

namespace {

// step.comp's numbers beside corofem_layout.h's kStep* (its comment says what each holds).
constexpr std::uint32_t kNone = 0xFFFFFFFFu;
constexpr std::size_t kWg = 64;  ///< nodes per work-group of step.comp (a segment's are whole ones)
constexpr std::size_t kChunk = 4096;
constexpr std::size_t kStates = static_cast<std::size_t>(StateSlot::kCount);
constexpr std::size_t kStateVecs = static_cast<std::size_t>(StateVec::kCount);
constexpr std::size_t kScratchVecs = static_cast<std::size_t>(Scratch::kCount);
constexpr std::size_t kVectors = kStates * kStateVecs + kScratchVecs;
enum Binding : std::size_t { kBindWgBody, kBindBodyU, kBindBodyR, kBindVecs, kBindInputs, kBindLoads, kBindPresc,
                             kBindPartials, kBindings };

template <class E>
std::size_t index(E e) {
  return static_cast<std::size_t>(e);
}

/// Vectors whose entries are positions: the device keeps them relative to the body's origin.
bool isPosition(StateVec v) { return v == StateVec::X; }
bool isPosition(Scratch v) { return v == Scratch::Xb || v == Scratch::Target; }

class VulkanStepStore final : public StepStore {
 public:
  VulkanStepStore(vkdevice::VulkanDevice& device, std::shared_ptr<vk::Context> ctx, bool isDouble,
                  const std::vector<BodySegment>& segments, std::size_t nodeTotal, DeviceSlot& slot)
      : device_(&device), slot_(&slot), generation_(slot.generation()), ctx_(std::move(ctx)), isDouble_(isDouble),
        rs_(isDouble ? sizeof(double) : sizeof(float)), dofTotal_(3 * nodeTotal) {
    if (segments.size() != slot.bodyCount())
      fail(ErrorCode::Internal, "vulkan step store: ", segments.size(), " segments for ", slot.bodyCount(), " bodies");
    for (std::size_t i = 0; i < segments.size(); ++i) {
      Body b;
      b.problem = &slot.problem(i);
      b.seg = segments[i];
      if (b.seg.dofs() != static_cast<std::size_t>(b.problem->restPositions.size()) || b.seg.nodeBegin % kWg != 0)
        fail(ErrorCode::Internal, "vulkan step store: body '", b.problem->name, "' has ", b.seg.dofs(),
             " dofs on the device at ", b.seg.dofBegin(), " for ", b.problem->restPositions.size());
      // In float, positions relative to the rest centroid keep float's resolution where the body
      // is (the device's own positions are relative to a centroid too); in double the origin is 0,
      // so that a state set and read back is the same numbers.
      if (!isDouble_) vkdevice::centroidOf(b.problem->restPositions, b.seg.nodes, b.origin.data());
      loads_ = std::max(loads_, b.problem->forces.size());
      groups_ = std::max(groups_, b.problem->prescribed.size());
      bodies_.push_back(std::move(b));
    }
    const vk::Spirv code = vk::shaderCode(vk::Shader::Step, isDouble_);
    pipeline_ = ctx_->pipeline(code.words, code.bytes, "step.comp");
    const std::size_t groups = dofTotal_ / (3 * kWg);
    buffers_[kBindWgBody] = vk::Buffer(*ctx_, groups * sizeof(std::uint32_t), false);
    buffers_[kBindBodyU] = vk::Buffer(*ctx_, bodies_.size() * kStepUCount * sizeof(std::uint32_t), false);
    buffers_[kBindVecs] = vk::Buffer(*ctx_, kVectors * dofTotal_ * rs_, false);
    buffers_[kBindInputs] = vk::Buffer(*ctx_, kStepInputs * dofTotal_ * rs_, false);
    buffers_[kBindPresc] = vk::Buffer(*ctx_, dofTotal_ * sizeof(std::uint32_t), false);
    buffers_[kBindPartials] = vk::Buffer(*ctx_, groups * kStepSums * rs_, false);
    placeholder_ = vk::Buffer(*ctx_, 0, false);
    up_ = vk::Buffer(*ctx_, std::max(dofTotal_ * rs_, dofTotal_ * sizeof(std::uint32_t)), true);
    down_ = vk::Buffer(*ctx_, std::max(dofTotal_ * rs_, groups * kStepSums * rs_), true);
    for (const Binding b : {kBindWgBody, kBindBodyU, kBindVecs, kBindInputs, kBindPartials}) vk::zeroBuffer(*ctx_, buffers_[b]);
    uploadWorkGroups();
    std::vector<std::uint32_t> none(dofTotal_, kNone);
    uploadWords(buffers_[kBindPresc], 0, none.data(), none.size());
    grow(loads_, groups_);
    // The slot may outlive the store or go first (a Simulation drops a group's slot before its
    // driver): the source holds the store's token, and does nothing once the store went.
    slot.setPositionSource(this, [this, alive = std::weak_ptr<char>(alive_)](std::size_t body, Eigen::VectorXd& x) {
      if (alive.expired()) return;
      Body& b = at(body);
      readVector(b, (kStateVecs * b.positions + index(StateVec::X)) * dofTotal_, true, x);
    });
  }

  ~VulkanStepStore() override {
    try {
      ctx_->wait(ctx_->flush());
      ctx_->freeDescriptorSet(set_);
    } catch (...) {
    }
  }

  // ---------------------------------------------------------------------------- vectors

  const Eigen::VectorXd& state(std::size_t body, StateSlot slot, StateVec vec) override {
    Body& b = at(body);
    Eigen::VectorXd& out = b.read[index(slot) * kStateVecs + index(vec)];
    readVector(b, stateOffset(b, slot, vec), isPosition(vec), out);
    return out;
  }

  void setState(std::size_t body, StateSlot slot, StateVec vec, const Eigen::VectorXd& value) override {
    Body& b = at(body);
    writeChecked(b, stateOffset(b, slot, vec), isPosition(vec), value, "a state vector");
  }

  void setZero(std::size_t body, StateSlot slot, StateVec vec) override {
    Body& b = at(body);
    if (isPosition(vec)) {
      writeVector(b, stateOffset(b, slot, vec), [&](Eigen::Index d) { return -b.origin[static_cast<std::size_t>(d % 3)]; });
      return;
    }
    VkCommandBuffer cb = ctx_->begin();
    vkCmdFillBuffer(cb, buffers_[kBindVecs].handle(), (stateOffset(b, slot, vec) + b.seg.dofBegin()) * rs_,
                    b.seg.dofs() * rs_, 0u);
    submitAndWait("a state cleared");
  }

  const Eigen::VectorXd& scratch(std::size_t body, Scratch vec) override {
    Body& b = at(body);
    Eigen::VectorXd& out = b.read[kStates * kStateVecs + index(vec)];
    readVector(b, scratchOffset(vec), isPosition(vec), out);
    return out;
  }

  void swap(std::size_t body, StateSlot a, StateSlot b) override {
    Body& s = at(body);
    std::swap(s.slot[index(a)], s.slot[index(b)]);  // the tables the passes read follow at their next dispatch
  }

  void copy(std::size_t body, StateSlot from, StateSlot to) override {
    Body& b = at(body);
    if (from == to) return;
    VkCommandBuffer cb = ctx_->begin();
    for (std::size_t v = 0; v < kStateVecs; ++v) {
      const VkBufferCopy region{(stateOffset(b, from, StateVec(v)) + b.seg.dofBegin()) * rs_,
                                (stateOffset(b, to, StateVec(v)) + b.seg.dofBegin()) * rs_, b.seg.dofs() * rs_};
      vkCmdCopyBuffer(cb, buffers_[kBindVecs].handle(), buffers_[kBindVecs].handle(), 1, &region);
    }
    submitAndWait("a state copied");
  }

  void problemChanged(std::size_t body) override { uploadProblem(checked(body)); }

  void setControls(std::size_t body, const BodyControls& controls) override {
    Body& b = at(body);
    b.controls = controls;
    uploadControls(b);
  }

  const BodyControls& controls(std::size_t body) const override { return bodies_.at(body).controls; }

  void removeBody(std::size_t body) override {
    checked(body);
    bodies_.erase(bodies_.begin() + static_cast<std::ptrdiff_t>(body));
    uploadWorkGroups();  // later bodies' indices moved down; the body's dofs belong to none
  }

  const Eigen::ArrayXd& freeMask(std::size_t body) const override { return bodies_.at(body).freeMask; }

  // ---------------------------------------------------------------------------- device calls
  // On the store's device, from and into its buffers; on another (the slot moved), through host
  // vectors.

  void setPositions(DeviceSlot& device, const BodySet& set, StateSlot slot) override {
    onDevice(device, "setPositions", [&](vkdevice::VulkanDevice& d) {
      std::vector<std::size_t> at;
      std::vector<std::array<double, 3>> origins;
      ConstVectors xs;
      for (std::size_t i : set) {
        at.push_back(stateOffset(bodies_[checked(i)], slot, StateVec::X));
        origins.push_back(bodies_[i].origin);
        if (d.positionsNeedHost()) xs.push_back(&state(i, slot, StateVec::X));
      }
      device.counted(SlotStats::SetPositions, set, [&]() {
        d.setPositionsFrom(set, buffers_[kBindVecs], at, origins, d.positionsNeedHost() ? &xs : nullptr);
      });
      for (std::size_t i : set) bodies_[i].positions = bodies_[i].slot[index(slot)];
      device.positionsSetElsewhere(set);
    }, [&]() {
      ConstVectors xs;
      for (std::size_t i : set) xs.push_back(&state(i, slot, StateVec::X));
      device.setPositions(set, xs);
    });
  }

  void internalForces(DeviceSlot& device, const BodySet& set) override {
    for (std::size_t i : set) checked(i);
    onDevice(device, "internalForces", [&](vkdevice::VulkanDevice& d) {
      device.counted(SlotStats::InternalForces, set, [&]() {
        d.internalForcesInto(set, buffers_[kBindVecs], std::vector<std::size_t>(set.size(), scratchOffset(Scratch::Fint)));
      });
    }, [&]() {
      std::vector<Eigen::VectorXd> f(set.size());
      Vectors fs;
      for (Eigen::VectorXd& v : f) fs.push_back(&v);
      device.internalForces(set, fs);
      for (std::size_t k = 0; k < set.size(); ++k) setScratch(at(set[k]), Scratch::Fint, f[k]);
    });
  }

  void damping(DeviceSlot& device, const BodySet& set, StateSlot slot) override {
    for (std::size_t i : set) checked(i);
    onDevice(device, "damping", [&](vkdevice::VulkanDevice& d) {
      // Mass damping alone (or none) as alpha M v in the store's pass, stiffness damping by the
      // device's product with C = alpha M + beta K.
      BodySet byMass, byProduct;
      Tables t = tables();
      for (std::size_t i : set) {
        const Problem& p = *bodies_[i].problem;
        if (p.rayleighStiffness == 0.0) {
          byMass.push_back(i);
          t.r[realsPerBody() * i + kStepRAlpha] = p.rayleighMass;
          t.u[kStepUCount * i + kStepUFrom] = static_cast<std::uint32_t>(index(slot));
        } else {
          byProduct.push_back(i);
        }
      }
      if (!byMass.empty()) run(kStepDamping, byMass, t, /*sums=*/false);
      if (!byProduct.empty()) {
        std::vector<std::size_t> from, to;
        for (std::size_t i : byProduct) {
          from.push_back(stateOffset(bodies_[i], slot, StateVec::V));
          to.push_back(scratchOffset(Scratch::Cv));
        }
        device.counted(SlotStats::Apply, byProduct, [&]() {
          d.applyIn(byProduct, std::vector<SystemCoeffs>(byProduct.size(), SystemCoeffs{0.0, 1.0, 0.0}),
                    buffers_[kBindVecs], from, to);
        });
      }
    }, [&]() {
      std::vector<Eigen::VectorXd> v(set.size()), cv(set.size());
      std::vector<const Problem*> problems;
      ConstVectors vs;
      Vectors cvs;
      for (std::size_t k = 0; k < set.size(); ++k) {
        v[k] = state(set[k], slot, StateVec::V);
        problems.push_back(bodies_[set[k]].problem);
        vs.push_back(&v[k]);
        cvs.push_back(&cv[k]);
      }
      dampingForces(device, set, problems, vs, cvs);
      for (std::size_t k = 0; k < set.size(); ++k) setScratch(bodies_[set[k]], Scratch::Cv, cv[k]);
    });
  }

  void solve(DeviceSlot& device, const BodySet& set, std::vector<PcgSolve>& solves) override {
    if (solves.size() != set.size())
      fail(ErrorCode::Internal, "step store: ", solves.size(), " solves for ", set.size(), " bodies");
    for (std::size_t i : set) checked(i);
    if (device.solver().linearSolver == LinearSolverKind::Pcg &&
        onDevice(device, "solve", [&](vkdevice::VulkanDevice& d) {
          d.stageSolve(set, buffers_[kBindVecs], std::vector<std::size_t>(set.size(), scratchOffset(Scratch::Rhs)));
          for (PcgSolve& s : solves) {
            s.b = nullptr;
            s.x = nullptr;
            s.resident = true;
          }
          device.counted(SlotStats::Solve, set, [&]() { solvePcg(d, set, solves, device.solver()); });
          d.takeSolution(set, buffers_[kBindVecs], std::vector<std::size_t>(set.size(), scratchOffset(Scratch::Dv)));
        }))
      return;
    for (PcgSolve& s : solves) s.resident = false;
    std::vector<Eigen::VectorXd> rhs(set.size()), dv(set.size());
    for (std::size_t k = 0; k < set.size(); ++k) {
      rhs[k] = scratch(set[k], Scratch::Rhs);
      dv[k].setZero(rhs[k].size());  // Newton's correction starts at 0
      solves[k].b = &rhs[k];
      solves[k].x = &dv[k];
    }
    device.solve(set, solves);
    for (std::size_t k = 0; k < set.size(); ++k) {
      setScratch(at(set[k]), Scratch::Dv, dv[k]);
      solves[k].b = nullptr;
      solves[k].x = nullptr;  // the temporaries go with this call
    }
  }

  // ---------------------------------------------------------------------------- passes

  void begin(const BodySet& set, const std::vector<BeginArgs>& args) override {
    check(set, args.size());
    Tables t = tables();
    for (std::size_t k = 0; k < set.size(); ++k) {
      const Body& b = bodies_[set[k]];
      const BeginArgs& a = args[k];
      setMaps(t, set[k], a.maps);
      std::uint32_t* u = &t.u[kStepUCount * set[k]];
      u[kStepUFrom] = static_cast<std::uint32_t>(index(a.from));
      double* r = &t.r[realsPerBody() * set[k]];
      r[kStepRFraction] = a.fraction;
      const std::vector<double> scales = b.problem->loadScales(a.t1, /*dynamic=*/true);
      const std::vector<double> presc = b.problem->prescribedScales(a.t1, /*dynamic=*/true);
      std::copy(scales.begin(), scales.end(), r + kStepRCount);
      std::copy(presc.begin(), presc.end(), r + kStepRCount + loads_);
    }
    run(kStepBegin, set, t, /*sums=*/false);
  }

  void positions(const BodySet& set, const std::vector<SchemeMaps>& maps) override {
    check(set, maps.size());
    Tables t = tables();
    for (std::size_t k = 0; k < set.size(); ++k) setMaps(t, set[k], maps[k]);
    run(kStepPositions, set, t, /*sums=*/false);
  }

  void residual(const BodySet& set, const std::vector<SchemeMaps>& maps, std::vector<ResidualSums>& out) override {
    check(set, maps.size());
    Tables t = tables();
    for (std::size_t k = 0; k < set.size(); ++k) setMaps(t, set[k], maps[k]);
    const std::vector<std::array<double, kStepSums>> sums = run(kStepResidual, set, t);
    out.resize(set.size());
    for (std::size_t k = 0; k < set.size(); ++k) {
      const auto& s = sums[k];
      out[k] = ResidualSums{s[0], s[1], s[2], s[3], s[4], s[5], s[6]};
    }
  }

  void update(const BodySet& set, std::vector<double>& nonFinite) override {
    check(set, set.size());
    const std::vector<std::array<double, kStepSums>> sums = run(kStepUpdate, set, tables());
    nonFinite.resize(set.size());
    for (std::size_t k = 0; k < set.size(); ++k) nonFinite[k] = sums[k][0];
  }

  void end(const BodySet& set, std::vector<EndSums>& out) override {
    check(set, set.size());
    const std::vector<std::array<double, kStepSums>> sums = run(kStepEnd, set, tables());
    out.resize(set.size());
    for (std::size_t k = 0; k < set.size(); ++k) std::copy_n(sums[k].begin(), out[k].size(), out[k].begin());
  }

 private:
  struct Body {
    const Problem* problem = nullptr;
    BodySegment seg;
    std::array<double, 3> origin = {0, 0, 0};  ///< subtracted from every position the device holds
    Eigen::ArrayXd freeMask;
    BodyControls controls;
    std::array<std::uint32_t, kStates> slot = {0, 1, 2, 3};  ///< the physical state of each StateSlot
    std::uint32_t positions = 0;  ///< the physical state whose X the device's positions were set from
    std::array<Eigen::VectorXd, kVectors> read;               ///< state() and scratch() answers
  };

  /// The per-body tables of one dispatch (every body of the store: those outside the set inactive).
  struct Tables {
    std::vector<std::uint32_t> u;
    std::vector<double> r;
  };

  std::size_t realsPerBody() const { return kStepRCount + loads_ + groups_; }

  Body& at(std::size_t body) { return bodies_[checked(body)]; }
  std::size_t checked(std::size_t body) const {
    if (body >= bodies_.size()) fail(ErrorCode::Internal, "step store: body ", body, " of ", bodies_.size());
    return body;
  }
  void check(const BodySet& set, std::size_t args) const {
    for (std::size_t body : set) checked(body);
    if (args != set.size())
      fail(ErrorCode::Internal, "step store: ", args, " arguments for ", set.size(), " bodies");
  }

  /// Where a vector starts in the vectors' buffer (reals; the body's entries from its dofBegin()).
  std::size_t stateOffset(const Body& b, StateSlot slot, StateVec vec) const {
    return (kStateVecs * b.slot[index(slot)] + index(vec)) * dofTotal_;
  }
  std::size_t scratchOffset(Scratch vec) const { return (kStates * kStateVecs + index(vec)) * dofTotal_; }

  /// out = the body's entries of the vector at `offset`, in double in the problem's numbering (the
  /// origin added back to positions).
  void readVector(const Body& b, std::size_t offset, bool position, Eigen::VectorXd& out) {
    VkCommandBuffer cb = ctx_->begin();
    const VkBufferCopy region{(offset + b.seg.dofBegin()) * rs_, b.seg.dofBegin() * rs_, b.seg.dofs() * rs_};
    vkCmdCopyBuffer(cb, buffers_[kBindVecs].handle(), down_.handle(), 1, &region);
    vk::hostReadBarrier(cb);
    submitAndWait("a read of the state");
    getReals(down_.mapped(), isDouble_, b.seg, kChunk, out);
    if (position)
      for (Eigen::Index d = 0; d < out.size(); ++d) out[d] += b.origin[static_cast<std::size_t>(d % 3)];
  }

  /// The body's entries of `to` from real `offset` on = value(problem dof), in the device's
  /// precision and numbering, through the staging buffer.
  template <class Value>
  void writeBody(const Body& b, const vk::Buffer& to, std::size_t offset, Value&& value) {
    putReals(up_.mapped(), isDouble_, b.seg.dofBegin(), b.seg.dofs(), kChunk,
             [&](std::size_t d) { return value(static_cast<Eigen::Index>(b.seg.hostDof(d))); });
    copyUp(to, (offset + b.seg.dofBegin()) * rs_, b.seg.dofBegin() * rs_, b.seg.dofs() * rs_);
  }
  template <class Value>
  void writeVector(const Body& b, std::size_t offset, Value&& value) {
    writeBody(b, buffers_[kBindVecs], offset, std::forward<Value>(value));
  }

  /// A state's or scratch vector of the body (3N entries, `what` in the message otherwise), less
  /// the origin where it holds positions.
  void writeChecked(const Body& b, std::size_t offset, bool position, const Eigen::VectorXd& value, const char* what) {
    if (static_cast<std::size_t>(value.size()) != b.seg.dofs())
      fail(ErrorCode::Internal, "step store: ", what, " of ", value.size(), " entries for body '", b.problem->name,
           "' of ", b.seg.dofs(), " dofs");
    writeVector(b, offset, [&](Eigen::Index d) {
      return value[d] - (position ? b.origin[static_cast<std::size_t>(d % 3)] : 0.0);
    });
  }

  void setScratch(const Body& b, Scratch vec, const Eigen::VectorXd& value) {
    writeChecked(b, scratchOffset(vec), isPosition(vec), value, "a scratch vector");
  }

  /// Input `k` of the body (kStepIn*) = value(problem dof).
  template <class Value>
  void writeInput(const Body& b, unsigned k, Value&& value) {
    writeBody(b, buffers_[kBindInputs], k * dofTotal_, std::forward<Value>(value));
  }

  void copyUp(const vk::Buffer& to, std::size_t toByte, std::size_t fromByte, std::size_t bytes) {
    VkCommandBuffer cb = ctx_->begin();
    const VkBufferCopy region{fromByte, toByte, bytes};
    vkCmdCopyBuffer(cb, up_.handle(), to.handle(), 1, &region);
    submitAndWait("an upload to the store");
  }

  void uploadWords(const vk::Buffer& to, std::size_t first, const std::uint32_t* words, std::size_t count) {
    if (count == 0) return;
    std::memcpy(up_.mapped(), words, count * sizeof(std::uint32_t));
    copyUp(to, first * sizeof(std::uint32_t), 0, count * sizeof(std::uint32_t));
  }

  /// Each node work-group's body (an index into bodies_), or none.
  void uploadWorkGroups() {
    std::vector<std::uint32_t> wg(dofTotal_ / (3 * kWg), kNone);
    for (std::size_t i = 0; i < bodies_.size(); ++i) {
      const BodySegment& s = bodies_[i].seg;
      for (std::size_t g = s.nodeBegin / kWg; g < (s.nodeBegin + s.nodeSpan) / kWg; ++g)
        wg[g] = static_cast<std::uint32_t>(i);
    }
    uploadWords(buffers_[kBindWgBody], 0, wg.data(), wg.size());
  }

  /// The body's per-dof inputs from its problem (rest positions, mass, free dofs, springs, the
  /// prescribed dofs' groups and values, the loads) and its controls.
  void uploadProblem(std::size_t body) {
    Body& b = bodies_[body];
    const Problem& p = *b.problem;
    b.freeMask = bodyScale(p).freeMask;
    const Eigen::Index n = p.restPositions.size();
    const auto originOf = [&](Eigen::Index d) { return b.origin[static_cast<std::size_t>(d % 3)]; };
    writeInput(b, kStepInRest, [&](Eigen::Index d) { return p.restPositions[d] - originOf(d); });
    writeInput(b, kStepInMass, [&](Eigen::Index d) { return p.lumpedMass.size() == n ? p.lumpedMass[d] : 0.0; });
    writeInput(b, kStepInFree, [&](Eigen::Index d) { return b.freeMask[d]; });
    writeInput(b, kStepInSpring, [&](Eigen::Index d) { return p.springStiffness.size() == n ? p.springStiffness[d] : 0.0; });
    // A prescribed dof takes the last group that names it (Problem::applyPrescribed).
    std::vector<std::uint32_t> group(static_cast<std::size_t>(n), kNone);
    Eigen::VectorXd value = Eigen::VectorXd::Zero(n);
    for (std::size_t g = 0; g < p.prescribed.size(); ++g)
      for (std::size_t k = 0; k < p.prescribed[g].dofs.size(); ++k) {
        group[p.prescribed[g].dofs[k]] = static_cast<std::uint32_t>(g);
        value[p.prescribed[g].dofs[k]] = p.prescribed[g].values[k];
      }
    writeInput(b, kStepInPresc, [&](Eigen::Index d) { return value[d]; });
    std::vector<std::uint32_t> deviceGroup(b.seg.dofs());
    for (std::size_t d = 0; d < b.seg.dofs(); ++d) deviceGroup[d] = group[b.seg.hostDof(d)];
    uploadWords(buffers_[kBindPresc], b.seg.dofBegin(), deviceGroup.data(), deviceGroup.size());
    if (p.forces.size() > loads_ || p.prescribed.size() > groups_) {
      grow(std::max(loads_, p.forces.size()), std::max(groups_, p.prescribed.size()));  // uploads every body again
      return;
    }
    for (std::size_t l = 0; l < loads_; ++l)
      writeBody(b, buffers_[kBindLoads], l * dofTotal_,
                [&](Eigen::Index d) { return l < p.forces.size() ? p.forces[l].f[d] : 0.0; });
    uploadControls(b);
  }

  /// Room for `loads` load patterns and `groups` prescribed groups a body: the buffers sized by them
  /// made again, the descriptor set written again, and every body's problem uploaded again.
  void grow(std::size_t loads, std::size_t groups) {
    ctx_->wait(ctx_->flush());  // recorded work may still read the buffers replaced
    loads_ = loads;
    groups_ = groups;
    buffers_[kBindBodyR] = vk::Buffer(*ctx_, std::max<std::size_t>(bodies_.size(), 1) * realsPerBody() * rs_, false);
    buffers_[kBindLoads] = vk::Buffer(*ctx_, std::max<std::size_t>(loads_, 1) * dofTotal_ * rs_, false);
    vk::zeroBuffer(*ctx_, buffers_[kBindLoads]);
    if (set_ != VK_NULL_HANDLE) ctx_->freeDescriptorSet(set_);
    std::vector<const vk::Buffer*> set(ctx_->bindings(), &placeholder_);
    for (std::size_t b = 0; b < kBindings; ++b) set[b] = &buffers_[b];
    set_ = ctx_->descriptorSet(set);
    for (std::size_t i = 0; i < bodies_.size(); ++i) uploadProblem(i);
  }

  /// The application's held targets (NaN: not held), applied forces and spring targets.
  void uploadControls(const Body& b) {
    const Eigen::Index n = b.problem->restPositions.size();
    const BodyControls& c = b.controls;
    const auto originOf = [&](Eigen::Index d) { return b.origin[static_cast<std::size_t>(d % 3)]; };
    if (c.targets.size() == n) writeInput(b, kStepInHeld, [&](Eigen::Index d) { return c.targets[d] - originOf(d); });
    if (c.forces.size() == n) writeInput(b, kStepInApplied, [&](Eigen::Index d) { return c.forces[d]; });
    if (c.springTargets.size() == n)
      writeInput(b, kStepInSpringTarget, [&](Eigen::Index d) { return c.springTargets[d] - originOf(d); });
  }

  /// The tables with every body inactive, its dofs and states set.
  Tables tables() const {
    Tables t;
    t.u.assign(kStepUCount * bodies_.size(), 0u);
    t.r.assign(realsPerBody() * bodies_.size(), 0.0);
    for (std::size_t i = 0; i < bodies_.size(); ++i) {
      const Body& b = bodies_[i];
      const Problem& p = *b.problem;
      const Eigen::Index n = p.restPositions.size();
      std::uint32_t* u = &t.u[kStepUCount * i];
      u[kStepUDofBegin] = static_cast<std::uint32_t>(b.seg.dofBegin());
      u[kStepUDofs] = static_cast<std::uint32_t>(b.seg.dofs());
      std::copy(b.slot.begin(), b.slot.end(), u + kStepUSlot);
      const bool springs = p.springStiffness.size() == n && b.controls.springTargets.size() == n;
      u[kStepUFlags] = (springs ? kStepFlagSprings : 0u) | (b.controls.forces.size() == n ? kStepFlagApplied : 0u) |
                   (b.controls.targets.size() == n ? kStepFlagHeld : 0u);
    }
    return t;
  }

  void setMaps(Tables& t, std::size_t body, const SchemeMaps& m) const {
    if (m.newmark) t.u[kStepUCount * body + kStepUFlags] |= kStepFlagNewmark;
    double* r = &t.r[realsPerBody() * body];
    r[kStepRH] = m.h;
    r[kStepRKa] = m.ka;
    r[kStepRKx] = m.kx;
    r[kStepRCv] = m.cv;
    r[kStepRCa] = m.ca;
  }

  /// Dispatches `mode` over every dof work-group with the set's bodies active, waits, and returns
  /// each body's sums: its work-groups' partial sums added in order, in double.
  std::vector<std::array<double, kStepSums>> run(unsigned mode, const BodySet& set, Tables t, bool sums = true) {
    for (std::size_t i : set) t.u[kStepUCount * i + kStepUActive] = 1u;
    VkCommandBuffer cb = ctx_->begin();
    vk::updateBuffer(cb, buffers_[kBindBodyU], 0, t.u.data(), t.u.size() * sizeof(std::uint32_t));
    const std::vector<unsigned char> reals = realBytes(t.r, isDouble_);
    vk::updateBuffer(cb, buffers_[kBindBodyR], 0, reals.data(), reals.size());
    vk::fullBarrier(cb);
    VulkanPush push;
    push.mode = mode;
    push.o[0] = static_cast<std::uint32_t>(dofTotal_);
    push.o[1] = static_cast<std::uint32_t>(loads_);
    push.o[2] = static_cast<std::uint32_t>(groups_);
    push.o[3] = static_cast<std::uint32_t>(realsPerBody());
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_);
    vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, ctx_->pipelineLayout(), 0, 1, &set_, 0, nullptr);
    vkCmdPushConstants(cb, ctx_->pipelineLayout(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(push), &push);
    vkCmdDispatch(cb, static_cast<std::uint32_t>(dofTotal_ / (3 * kWg)), 1, 1);
    vk::fullBarrier(cb);
    if (!sums) return {};  // left open: the next call that waits submits it
    for (std::size_t i : set) {
      const BodySegment& s = bodies_[i].seg;
      const std::size_t first = s.nodeBegin / kWg, count = (s.nodes + kWg - 1) / kWg;
      const VkBufferCopy region{first * kStepSums * rs_, first * kStepSums * rs_, count * kStepSums * rs_};
      if (count) vkCmdCopyBuffer(cb, buffers_[kBindPartials].handle(), down_.handle(), 1, &region);
    }
    vk::hostReadBarrier(cb);
    submitAndWait("the step's passes");
    std::vector<std::array<double, kStepSums>> out(set.size());
    for (std::size_t k = 0; k < set.size(); ++k) {
      const BodySegment& s = bodies_[set[k]].seg;
      const std::size_t first = s.nodeBegin / kWg, count = (s.nodes + kWg - 1) / kWg;
      out[k].fill(0.0);
      withReals(down_.mapped(), isDouble_, 0, [&](const auto* p) {
        for (std::size_t g = first; g < first + count; ++g)
          for (std::size_t j = 0; j < kStepSums; ++j) out[k][j] += static_cast<double>(p[kStepSums * g + j]);
      });
    }
    return out;
  }

  /// Whether the slot still holds the store's device (the generation it was made in), and has not
  /// given up on every device.
  bool holdsMine(const DeviceSlot& slot) const {
    return !slot.exhausted() && slot.generation() == generation_ && &slot.device() == static_cast<Device*>(device_);
  }

  /// Submits the open commands and waits. A DeviceError there (the device failed under the store's
  /// own commands) moves the slot to its next candidate, as an error in a call of the slot's would,
  /// and is thrown on: the step fails, and the driver moves the states at the next
  /// (DynamicsDriver::followDevice).
  void submitAndWait(const char* what) {
    try {
      ctx_->wait(ctx_->submit());
    } catch (const Error& e) {
      if (e.code() == ErrorCode::DeviceError && holdsMine(*slot_)) slot_->failover(what, e);
      throw;
    }
  }

  /// onDevice(device) where the slot still holds the store's device; a DeviceError there moves the
  /// slot to its next candidate (unless a wait inside it did already). Then, or where the slot held
  /// another device already, onHost() (through the slot). Returns whether onDevice ran to its end.
  template <class OnDevice, class OnHost>
  bool onDevice(DeviceSlot& slot, const char* call, OnDevice&& onDevice, OnHost&& onHost) {
    if (holdsMine(slot)) {
      try {
        onDevice(*device_);
        return true;
      } catch (const Error& e) {
        if (e.code() != ErrorCode::DeviceError) throw;
        if (holdsMine(slot)) slot.failover(call, e);  // the new device takes the store's positions (the source)
      }
    }
    onHost();
    return false;
  }
  template <class OnDevice>
  bool onDevice(DeviceSlot& slot, const char* call, OnDevice&& fn) {
    return onDevice(slot, call, std::forward<OnDevice>(fn), []() {});
  }

  vkdevice::VulkanDevice* device_;  ///< the device whose context holds the store
  DeviceSlot* slot_;                ///< the slot it was made for (never used in the destructor)
  std::size_t generation_;          ///< the slot's generation when it held device_
  std::shared_ptr<char> alive_ = std::make_shared<char>(0);  ///< the slot's position source's token
  std::shared_ptr<vk::Context> ctx_;
  bool isDouble_;
  std::size_t rs_;
  std::size_t dofTotal_;
  std::vector<Body> bodies_;
  std::size_t loads_ = 0, groups_ = 0;  ///< the most load patterns and prescribed groups of a body
  VkPipeline pipeline_ = VK_NULL_HANDLE;
  std::array<vk::Buffer, kBindings> buffers_;
  vk::Buffer placeholder_, up_, down_;
  VkDescriptorSet set_ = VK_NULL_HANDLE;
};

}  // namespace

std::unique_ptr<StepStore> createVulkanStepStore(vkdevice::VulkanDevice& device, std::shared_ptr<vk::Context> ctx,
                                                 bool isDouble, const std::vector<BodySegment>& segments,
                                                 std::size_t nodeTotal, DeviceSlot& slot) {
  return std::make_unique<VulkanStepStore>(device, std::move(ctx), isDouble, segments, nodeTotal, slot);
}

}  // namespace corofem::detail
