// The host's StepStore (solve/step_store.hpp): every vector in double in the problem's numbering,
// the passes on the host's threads.
#include "solve/step_store.hpp"

#include "solve/body_scale.hpp"
#include "solve/device_slot.hpp"

#include "util/error.hpp"
#include "util/parallel.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

namespace corofem::detail {

namespace {

/// fn(i) for every i < n on the host's threads (each i a body's own work: no shared writes).
template <class Fn>
void forEach(std::size_t n, Fn&& fn) {
  parallelChunks(n, 1, [&](std::size_t, std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) fn(i);
  });
}

/// Dofs of one body per chunk of the host's threads in the passes. A body of at most this many
/// dofs runs on one thread, its sums in dof order; a larger one's sums are taken per chunk, then
/// added in chunk order: the same bits with any number of threads, and a body gets the same bits
/// alone as in a batch.
constexpr std::size_t kDofChunk = 16384;

/// chunkSums over a body's n dofs in chunks of kDofChunk, fn(begin, end, sums) on Eigen indices.
template <std::size_t K, class Fn>
std::array<double, K> overDofs(Eigen::Index n, Fn&& fn) {
  return chunkSums<K>(static_cast<std::size_t>(n), kDofChunk, [&](std::size_t lo, std::size_t hi, std::array<double, K>& sums) {
    fn(static_cast<Eigen::Index>(lo), static_cast<Eigen::Index>(hi), sums);
  });
}

constexpr std::size_t kStates = static_cast<std::size_t>(StateSlot::kCount);
constexpr std::size_t kStateVecs = static_cast<std::size_t>(StateVec::kCount);
constexpr std::size_t kScratch = static_cast<std::size_t>(Scratch::kCount);

class HostStepStore final : public StepStore {
 public:
  explicit HostStepStore(const DeviceSlot& slot) {
    bodies_.resize(slot.bodyCount());
    for (std::size_t i = 0; i < bodies_.size(); ++i) {
      bodies_[i].problem = &slot.problem(i);
      bodies_[i].freeMask = bodyScale(slot.problem(i)).freeMask;
    }
  }

  const Eigen::VectorXd& state(std::size_t body, StateSlot slot, StateVec vec) override {
    return at(body).states[index(slot)][index(vec)];
  }
  void setState(std::size_t body, StateSlot slot, StateVec vec, const Eigen::VectorXd& value) override {
    Body& b = at(body);
    if (value.size() != b.problem->restPositions.size())
      fail(ErrorCode::Internal, "step store: a state vector of ", value.size(), " entries for body '", b.problem->name,
           "' of ", b.problem->restPositions.size(), " dofs");
    b.states[index(slot)][index(vec)] = value;
  }
  void setZero(std::size_t body, StateSlot slot, StateVec vec) override {
    Body& b = at(body);
    b.states[index(slot)][index(vec)].setZero(b.problem->restPositions.size());
  }
  const Eigen::VectorXd& scratch(std::size_t body, Scratch vec) override { return at(body).scratch[index(vec)]; }
  void swap(std::size_t body, StateSlot a, StateSlot b) override {
    std::swap(at(body).states[index(a)], at(body).states[index(b)]);  // each vector's buffer, not its entries
  }
  void copy(std::size_t body, StateSlot from, StateSlot to) override {
    at(body).states[index(to)] = at(body).states[index(from)];
  }
  void problemChanged(std::size_t body) override { at(body).freeMask = bodyScale(*at(body).problem).freeMask; }
  void setControls(std::size_t body, const BodyControls& controls) override { at(body).controls = controls; }
  const BodyControls& controls(std::size_t body) const override { return bodies_.at(body).controls; }
  void removeBody(std::size_t body) override {
    at(body);
    bodies_.erase(bodies_.begin() + static_cast<std::ptrdiff_t>(body));
  }
  const Eigen::ArrayXd& freeMask(std::size_t body) const override { return bodies_.at(body).freeMask; }

  void setPositions(DeviceSlot& device, const BodySet& set, StateSlot slot) override {
    ConstVectors xs;
    for (std::size_t i : set) xs.push_back(&at(i).states[index(slot)][index(StateVec::X)]);
    device.setPositions(set, xs);
  }
  void internalForces(DeviceSlot& device, const BodySet& set) override {
    Vectors fs;
    for (std::size_t i : set) fs.push_back(&at(i).scratch[index(Scratch::Fint)]);
    device.internalForces(set, fs);
  }
  void damping(DeviceSlot& device, const BodySet& set, StateSlot slot) override {
    std::vector<const Problem*> problems;
    ConstVectors v;
    Vectors cv;
    for (std::size_t i : set) {
      Body& b = at(i);
      problems.push_back(b.problem);
      v.push_back(&b.states[index(slot)][index(StateVec::V)]);
      cv.push_back(&b.scratch[index(Scratch::Cv)]);
    }
    dampingForces(device, set, problems, v, cv);
  }
  void solve(DeviceSlot& device, const BodySet& set, std::vector<PcgSolve>& solves) override {
    for (std::size_t k = 0; k < set.size(); ++k) {
      Body& b = at(set[k]);
      solves[k].b = &b.scratch[index(Scratch::Rhs)];
      solves[k].x = &b.scratch[index(Scratch::Dv)];
      solves[k].x->setZero(b.problem->restPositions.size());  // Newton's correction starts at 0
    }
    device.solve(set, solves);
  }

  void begin(const BodySet& set, const std::vector<BeginArgs>& args) override {
    check(set, args.size());
    forEach(set.size(), [&](std::size_t k) {
      Body& b = at(set[k]);
      const BeginArgs& arg = args[k];
      const SchemeMaps& m = arg.maps;
      const Problem& p = *b.problem;
      const Eigen::Index n = p.restPositions.size();
      auto& now = b.states[index(StateSlot::Committed)];
      auto& next = b.states[index(StateSlot::Result)];
      const Eigen::VectorXd &x = now[index(StateVec::X)], &v = now[index(StateVec::V)], &a = now[index(StateVec::A)];
      for (Eigen::VectorXd& s : b.scratch) s.resize(n);
      for (Eigen::VectorXd& s : next) s.resize(n);
      // The targets, read on constrained dofs only (the other entries are left as they were).
      Eigen::VectorXd& target = b.scratch[index(Scratch::Target)];
      p.applyPrescribed(target, arg.t1, /*dynamic=*/true);
      const Eigen::VectorXd& held = b.controls.targets;
      if (held.size() == n) {
        const Eigen::VectorXd& x0 = b.states[index(arg.from)][index(StateVec::X)];
        for (Eigen::Index d = 0; d < n; ++d)
          if (!std::isnan(held[d]))
            target[d] = arg.fraction == 1.0 ? held[d] : x0[d] + arg.fraction * (held[d] - x0[d]);
      }
      const std::vector<double> scales = p.loadScales(arg.t1, /*dynamic=*/true);
      const Eigen::VectorXd& applied = b.controls.forces;
      const bool withApplied = applied.size() == n;
      Eigen::VectorXd &vb = b.scratch[index(Scratch::Vb)], &xb = b.scratch[index(Scratch::Xb)],
                      &cvOut = b.scratch[index(Scratch::Cv)];
      Eigen::VectorXd &fext = next[index(StateVec::Fext)], &vOut = next[index(StateVec::V)];
      const Eigen::ArrayXd& free = b.freeMask;
      // One pass: vb, xb, f_ext (the loads, then the application's forces), and Newton's starting
      // v. The same arithmetic, term by term, as the vector expressions it fuses.
      overDofs<0>(n, [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 0>&) {
        for (Eigen::Index d = lo; d < hi; ++d) {
          const double vbd = m.newmark ? v[d] + m.cv * a[d] : v[d];
          const double xbd = m.newmark ? x[d] + m.h * v[d] + m.ca * a[d] - m.kx * vbd : x[d];
          vb[d] = vbd;
          xb[d] = xbd;
          double f = p.externalForceAt(scales, d);
          if (withApplied) f += applied[d];
          fext[d] = f;
          vOut[d] = free[d] == 0.0 ? (target[d] - xbd) / m.kx : v[d];
          cvOut[d] = 0.0;
        }
      });
    });
  }

  void positions(const BodySet& set, const std::vector<SchemeMaps>& maps) override {
    check(set, maps.size());
    forEach(set.size(), [&](std::size_t k) {
      Body& b = at(set[k]);
      const SchemeMaps& m = maps[k];
      auto& next = b.states[index(StateSlot::Result)];
      const Eigen::VectorXd &v = next[index(StateVec::V)], &vb = b.scratch[index(Scratch::Vb)],
                            &xb = b.scratch[index(Scratch::Xb)];
      Eigen::VectorXd &x = next[index(StateVec::X)], &a = next[index(StateVec::A)];
      overDofs<0>(v.size(), [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 0>&) {
        for (Eigen::Index d = lo; d < hi; ++d) {
          x[d] = xb[d] + m.kx * v[d];
          a[d] = m.ka * (v[d] - vb[d]);
        }
      });
    });
  }

  void residual(const BodySet& set, const std::vector<SchemeMaps>& maps, std::vector<ResidualSums>& out) override {
    check(set, maps.size());
    out.assign(set.size(), ResidualSums{});
    forEach(set.size(), [&](std::size_t k) {
      Body& b = at(set[k]);
      const double ka = maps[k].ka;
      const Problem& p = *b.problem;
      const Eigen::VectorXd& mass = p.lumpedMass;
      const Eigen::Index n = p.restPositions.size();
      auto& next = b.states[index(StateSlot::Result)];
      const Eigen::VectorXd &x = next[index(StateVec::X)], &v = next[index(StateVec::V)], &a = next[index(StateVec::A)],
                            &fext = next[index(StateVec::Fext)], &cv = b.scratch[index(Scratch::Cv)],
                            &fint = b.scratch[index(Scratch::Fint)];
      Eigen::VectorXd &r = b.scratch[index(Scratch::R)], &rhs = b.scratch[index(Scratch::Rhs)];
      // The springs' S (x - t) joins f_int here (a zero vector's worth of work without springs).
      const Eigen::VectorXd& ks = p.springStiffness;
      const Eigen::VectorXd& springTarget = b.controls.springTargets;
      const bool springs = ks.size() == n && springTarget.size() == n;
      const Eigen::ArrayXd& free = b.freeMask;
      // Sums: |M a|^2, |C v|^2, |f_int|^2, |S (x - t)|^2, |r|^2 (free dofs), non-finite x, v or a,
      // |f_ext|^2 (free dofs). The sums run in dof order.
      const std::array<double, 7> sums = overDofs<7>(n, [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 7>& sum) {
        for (Eigen::Index d = lo; d < hi; ++d) {
          const double ma = mass[d] * a[d];
          const double spring = springs && ks[d] != 0.0 ? ks[d] * (x[d] - springTarget[d]) : 0.0;
          const double rd = ma + cv[d] + fint[d] + spring - fext[d];
          r[d] = rd;
          rhs[d] = -rd / ka;
          const double f = free[d], maf = ma * f, cvf = cv[d] * f, fintf = fint[d] * f, sf = spring * f, rf = rd * f,
                       ff = fext[d] * f;
          sum[0] += maf * maf;
          sum[1] += cvf * cvf;
          sum[2] += fintf * fintf;
          sum[3] += sf * sf;
          sum[4] += rf * rf;
          if (!std::isfinite(x[d]) || !std::isfinite(v[d]) || !std::isfinite(a[d])) sum[5] += 1.0;
          sum[6] += ff * ff;
        }
      });
      out[k] = ResidualSums{sums[0], sums[1], sums[2], sums[3], sums[4], sums[5], sums[6]};
    });
  }

  void update(const BodySet& set, std::vector<double>& nonFinite) override {
    check(set);
    nonFinite.assign(set.size(), 0.0);
    forEach(set.size(), [&](std::size_t k) {
      Body& b = at(set[k]);
      Eigen::VectorXd& v = b.states[index(StateSlot::Result)][index(StateVec::V)];
      const Eigen::VectorXd& dv = b.scratch[index(Scratch::Dv)];
      const std::array<double, 1> bad = overDofs<1>(v.size(), [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 1>& sum) {
        for (Eigen::Index d = lo; d < hi; ++d) {
          if (!std::isfinite(dv[d])) sum[0] += 1.0;
          v[d] += dv[d];
        }
      });
      nonFinite[k] = bad[0];
    });
  }

  void end(const BodySet& set, std::vector<EndSums>& out) override {
    check(set);
    out.assign(set.size(), EndSums{});
    forEach(set.size(), [&](std::size_t k) {
      Body& b = at(set[k]);
      const Problem& p = *b.problem;
      const Eigen::VectorXd& mass = p.lumpedMass;
      const Eigen::Index n = p.restPositions.size();
      const Eigen::VectorXd& ks = p.springStiffness;
      const Eigen::VectorXd& springTarget = b.controls.springTargets;
      const bool springs = ks.size() == n && springTarget.size() == n;
      const auto& now = b.states[index(StateSlot::Committed)];
      auto& next = b.states[index(StateSlot::Result)];
      const Eigen::VectorXd &x0 = now[index(StateVec::X)], &fextPrev = now[index(StateVec::Fext)],
                            &reactionPrev = now[index(StateVec::Reaction)];
      const Eigen::VectorXd &x = next[index(StateVec::X)], &v = next[index(StateVec::V)],
                            &r = b.scratch[index(Scratch::R)];
      Eigen::VectorXd &fext = next[index(StateVec::Fext)], &reaction = next[index(StateVec::Reaction)];
      reaction.resize(n);
      const Eigen::ArrayXd& free = b.freeMask;
      out[k] = overDofs<7>(n, [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 7>& sum) {
        for (Eigen::Index d = lo; d < hi; ++d) {
          const double rd = r[d] * (1.0 - free[d]);
          reaction[d] = rd;
          if (springs && ks[d] != 0.0 && free[d] != 0.0) fext[d] += ks[d] * (springTarget[d] - x[d]);
          const double dx = x[d] - x0[d], f = fext[d];
          sum[0] += (reactionPrev[d] + rd) * dx;
          sum[1] += (fextPrev[d] + f) * dx;
          sum[2] += reactionPrev[d] * dx;
          sum[3] += rd * dx;
          sum[4] += fextPrev[d] * dx;
          sum[5] += f * dx;
          sum[6] += mass[d] * (v[d] * v[d]);
        }
      });
    });
  }

 private:
  struct Body {
    const Problem* problem = nullptr;
    Eigen::ArrayXd freeMask;
    BodyControls controls;
    std::array<std::array<Eigen::VectorXd, kStateVecs>, kStates> states;
    std::array<Eigen::VectorXd, kScratch> scratch;
  };

  template <class E>
  static std::size_t index(E e) {
    return static_cast<std::size_t>(e);
  }
  Body& at(std::size_t body) {
    if (body >= bodies_.size())
      fail(ErrorCode::Internal, "step store: body ", body, " of ", bodies_.size());
    return bodies_[body];
  }
  /// Throws Error(Internal) for a body the store lacks, before a pass's tasks run (which must not
  /// throw).
  void check(const BodySet& set) {
    for (std::size_t body : set) at(body);
  }
  /// check(set), and Error(Internal) for per-body arguments of another count.
  void check(const BodySet& set, std::size_t args) {
    check(set);
    if (args != set.size())
      fail(ErrorCode::Internal, "step store: ", args, " arguments for ", set.size(), " bodies");
  }

  std::vector<Body> bodies_;
};

}  // namespace

void dampingForces(DeviceSlot& device, const BodySet& set, const std::vector<const Problem*>& problems,
                   const ConstVectors& v, const Vectors& cv) {
  // Mass damping alone (beta = 0, the common "air drag") is a scaling of the lumped mass: formed
  // here in double, the same expression and bits as the reference device's apply, with no device
  // call (on a device that call is an upload, a product and a read per force evaluation).
  BodySet stiff;
  ConstVectors stiffV;
  Vectors stiffCv;
  for (std::size_t k = 0; k < set.size(); ++k) {
    const Problem& p = *problems[k];
    if (p.rayleighMass == 0.0 && p.rayleighStiffness == 0.0) {
      cv[k]->setZero(v[k]->size());
    } else if (p.rayleighStiffness == 0.0 && p.lumpedMass.size() == v[k]->size()) {
      *cv[k] = p.rayleighMass * p.lumpedMass.cwiseProduct(*v[k]);
    } else {
      stiff.push_back(set[k]);
      stiffV.push_back(v[k]);
      stiffCv.push_back(cv[k]);
    }
  }
  if (!stiff.empty())
    device.apply(stiff, std::vector<SystemCoeffs>(stiff.size(), SystemCoeffs{0.0, 1.0, 0.0}), stiffV, stiffCv);
}

std::unique_ptr<StepStore> createHostStepStore(const DeviceSlot& slot) { return std::make_unique<HostStepStore>(slot); }

}  // namespace corofem::detail
