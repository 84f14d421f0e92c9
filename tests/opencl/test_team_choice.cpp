// The choice between a team of work-groups and one work-group per body (backends/opencl/
// team_choice.hpp), driven with synthetic times per iteration: a quiet machine keeps the team, a
// busy core moves the rounds to one work-group within a few solves and back after it is gone, and a
// process pinned to fewer CPUs than the team pays for few team rounds.
#include "backends/opencl/team_choice.hpp"

#include <gtest/gtest.h>

#include <functional>

namespace corofem {
namespace {

using detail::TeamChoice;
using Way = TeamChoice::Way;

/// Runs `rounds` rounds with the times per iteration cost(way, round); returns how many took the team.
int run(TeamChoice& c, int first, int rounds, const std::function<double(Way, int)>& cost) {
  int team = 0;
  for (int k = first; k < first + rounds; ++k) {
    const Way w = c.next();
    team += w == Way::Team ? 1 : 0;
    c.measured(w, cost(w, k));
  }
  return team;
}

TEST(TeamChoice, AQuietMachineKeepsTheTeamAndProbesTheOtherWayRarely) {
  // The 12,960-tet beam's times on 2 quiet cores: team 35, one work-group 57 (ms a step).
  TeamChoice c;
  EXPECT_EQ(c.next(), Way::Team);  // the team first
  c.measured(Way::Team, 35);
  EXPECT_EQ(c.next(), Way::Group);  // then one probe of the other way
  c.measured(Way::Group, 57);
  const int team = run(c, 0, 1000, [](Way w, int) { return w == Way::Team ? 35.0 : 57.0; });
  EXPECT_GE(team, 990) << "probes of the slower way back off to one every " << TeamChoice::kMaxInterval << " rounds";
  EXPECT_LT(team, 1000) << "the slower way is still probed now and then";
  EXPECT_EQ(c.current(), Way::Team);
}

TEST(TeamChoice, ABusyCoreMovesTheRoundsToOneWorkGroupAndTheyComeBackWhenItIsGone) {
  // Quiet until round 300, a busy core until 1300 (team 73, group 55), quiet again after.
  auto cost = [](Way w, int k) {
    const bool busy = k >= 300 && k < 1300;
    return w == Way::Team ? (busy ? 73.0 : 35.0) : (busy ? 55.0 : 57.0);
  };
  TeamChoice c;
  run(c, 0, 300, cost);
  EXPECT_EQ(c.current(), Way::Team);
  run(c, 300, 5, cost);
  EXPECT_EQ(c.current(), Way::Group) << "within a few solves of the busy core";
  const int teamWhileBusy = run(c, 305, 995, cost);
  EXPECT_LE(teamWhileBusy, 12) << "probes of the team while the core is busy";
  EXPECT_EQ(c.current(), Way::Group);
  // Back within one probe interval at most.
  run(c, 1300, static_cast<int>(TeamChoice::kMaxInterval) + 2, cost);
  EXPECT_EQ(c.current(), Way::Team);
}

TEST(TeamChoice, APinnedProcessPaysForFewTeamRounds) {
  // Members taking turns on one CPU: the team 60 times slower than one work-group (more than 4x:
  // the probes back off by 8 at a time).
  TeamChoice c;
  const int team = run(c, 0, 2000, [](Way w, int) { return w == Way::Team ? 60.0 : 1.0; });
  EXPECT_LE(team, 4) << "the first round, then probes after 8, 64 and 512 rounds";
  EXPECT_EQ(c.current(), Way::Group);
}

TEST(TeamChoice, NoiseWithinTheMarginDoesNotFlipIt) {
  TeamChoice c;
  // The two ways within 3 % of each other, alternating which is ahead.
  run(c, 0, 500, [](Way w, int k) { return w == Way::Team ? 1.0 : (k % 2 ? 0.98 : 1.02); });
  EXPECT_EQ(c.current(), Way::Team);
}

TEST(TeamChoice, ARoundWithoutIterationsTeachesNothing) {
  TeamChoice c;
  EXPECT_EQ(c.next(), Way::Team);
  c.measured(Way::Team, 0.0);  // a warm start that had converged: no iteration
  EXPECT_EQ(c.next(), Way::Team) << "still to be measured";
  c.measured(Way::Team, 2.0);
  EXPECT_EQ(c.next(), Way::Group);
}

}  // namespace
}  // namespace corofem
