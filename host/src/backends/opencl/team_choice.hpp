// Which way a CPU device runs a round of fewer bodies than cores, chosen by measurement: a team of
// work-groups per body on every core (pcg_iterate_team), or a work-group per body on one core
// (pcg_iterate_group). Both run the same iterations on the same items and give the same bits, so
// the choice changes the time of a solve, never its answer.
//
// Why measure: a team's members wait for each other at every phase of every iteration. On a quiet
// machine that is the fastest way (the 12,960-tet beam of bench/bench_contention.cpp with the
// diagonal: 35 ms a step against 52 launched and 57 on one core); while another process takes a
// core, the member the OS has parked holds the others up (73 ms, against 55 on one core). Only the
// time per iteration shows which case the application is in, and it changes while it runs.
//
// The rule: the team first, then one probe of the group; afterwards the cheaper of the two, whose
// time per iteration is followed solve by solve (a mean of the last ones), and every `interval`
// solves one probe of the other. A probe that loses doubles the interval (up to kMaxInterval), or
// multiplies it by 8 up to kMaxFarInterval where it was more than 4 times as slow (a process pinned
// to fewer CPUs than the team's members pays a team's solve many times over; on Linux tuning.cpp
// does not offer teams to it at all; a busy core makes a team about 1.3 times as slow); one that
// wins takes over and resets it. A switch needs a margin of kMargin, so that noise does not flip
// it. The times are per iteration and element, so that rounds of other bodies compare.
#pragma once

#include <algorithm>
#include <cstddef>

namespace corofem::detail {

class TeamChoice {
 public:
  enum class Way { Team, Group };

  static constexpr std::size_t kFirstInterval = 8;
  static constexpr std::size_t kMaxInterval = 256;
  static constexpr std::size_t kMaxFarInterval = 4096;  ///< after a probe more than 4 times as slow
  static constexpr double kMargin = 0.05;

  /// The way the next round runs.
  Way next() {
    if (!known_[index(Way::Team)]) return probe(Way::Team);
    if (!known_[index(Way::Group)]) return probe(Way::Group);
    if (since_ >= interval_) return probe(other(current_));
    probing_ = false;
    return current_;
  }

  /// A round that ran `way` took `secondsPerIteration` (the next() before it chose it).
  void measured(Way way, double secondsPerIteration) {
    const std::size_t i = index(way);
    if (!(secondsPerIteration > 0)) return;  // nothing iterated: nothing learnt
    if (probing_ || !known_[i]) {
      cost_[i] = secondsPerIteration;
      known_[i] = true;
      probing_ = false;
      since_ = 0;
      const double mine = cost_[i], theirs = cost_[index(other(way))];
      if (way == current_ || !known_[index(current_)]) return;
      if (mine < (1 - kMargin) * theirs) {
        current_ = way;
        interval_ = kFirstInterval;
      } else {
        interval_ = mine > 4 * theirs ? std::min(kMaxFarInterval, interval_ * 8) : std::min(kMaxInterval, interval_ * 2);
      }
      return;
    }
    // The way in use: a running mean of its last solves. It is dropped at once where it grew past
    // the other's last probe (another process took a core).
    cost_[i] = 0.5 * cost_[i] + 0.5 * secondsPerIteration;
    ++since_;
    const std::size_t o = index(other(way));
    if (known_[o] && cost_[o] < (1 - kMargin) * cost_[i]) {
      current_ = other(way);
      since_ = 0;
      interval_ = kFirstInterval;
    }
  }

  Way current() const { return current_; }

 private:
  static std::size_t index(Way w) { return w == Way::Team ? 0 : 1; }
  static Way other(Way w) { return w == Way::Team ? Way::Group : Way::Team; }
  Way probe(Way w) {
    probing_ = true;
    return w;
  }

  Way current_ = Way::Team;
  double cost_[2] = {0, 0};   ///< seconds per iteration, per way
  bool known_[2] = {false, false};
  bool probing_ = false;      ///< the round next() gave is a probe
  std::size_t since_ = 0;     ///< rounds of the current way since the last probe
  std::size_t interval_ = kFirstInterval;
};

}  // namespace corofem::detail
