#include "rcal/kinematics/identifiability.hpp"

#include <gtest/gtest.h>

#include "test_robots.hpp"

namespace rcal::kinematics {
namespace {

using namespace testing;

std::vector<Eigen::VectorXd> RandomPoses(const KinematicModel& m, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<Eigen::VectorXd> qs;
  for (int i = 0; i < count; ++i) qs.push_back(RandomJoints(m, rng));
  return qs;
}

std::string AllExplanations(const IdentifiabilityReport& r) {
  std::string s;
  for (const auto& c : r.unidentifiable) s += c.explanation + "\n";
  return s;
}

bool Explains(const IdentifiabilityReport& r, const std::string& text) {
  return AllExplanations(r).find(text) != std::string::npos;
}

TEST(Identifiability, Grb3016GenericToolRanks) {
  const KinematicModel m = Grb3016();  // generic tool a=10 mm, α=0.1, d=50 mm, θ=0.2
  const auto qs = RandomPoses(m, 50, 1);
  const auto full = AnalyzeIdentifiability(m, qs, m.Nominal(), MeasurementKind::kFullPose);
  EXPECT_EQ(full.num_params, 28);
  EXPECT_EQ(full.rank, 25) << AllExplanations(full);
  EXPECT_EQ(full.identifiable.size(), 25u);
  // Joints 2 and 3 are parallel (α2 = −π makes z2 = −z1): only d2 − d3 is seen.
  EXPECT_TRUE(Explains(full, "d3 and d2 enter only as d3 - d2")) << AllExplanations(full);
  // The tool transform overlaps joint 6 (α6 = 0, a6 = 0): θ and d act along the same axis, so only
  // their sums are seen.
  EXPECT_TRUE(Explains(full, "tool_theta and theta6 enter only as tool_theta + theta6"))
      << AllExplanations(full);
  EXPECT_TRUE(Explains(full, "tool_d and d6 enter only as tool_d + d6")) << AllExplanations(full);

  const auto pos = AnalyzeIdentifiability(m, qs, m.Nominal(), MeasurementKind::kPositionOnly);
  EXPECT_EQ(pos.rank, 22) << AllExplanations(pos);
  EXPECT_TRUE(Explains(pos, "tool_alpha has no effect on the measured poses"))
      << AllExplanations(pos);
}

TEST(Identifiability, Grb3016ZeroToolRanks) {
  const KinematicModel m = Grb3016(0, 0, 0, 0);
  const auto qs = RandomPoses(m, 50, 2);
  const auto full = AnalyzeIdentifiability(m, qs, m.Nominal(), MeasurementKind::kFullPose);
  EXPECT_EQ(full.rank, 23) << AllExplanations(full);
  const auto pos = AnalyzeIdentifiability(m, qs, m.Nominal(), MeasurementKind::kPositionOnly);
  EXPECT_EQ(pos.rank, 19) << AllExplanations(pos);
  // Each lost rank is explained by exactly one combination.
  EXPECT_EQ(full.unidentifiable.size(), 5u);
  EXPECT_EQ(pos.unidentifiable.size(), 9u);
}

TEST(Identifiability, BaseSetHasFullRankAndExplanationsAreNullDirections) {
  const KinematicModel m = Grb3016();
  const auto qs = RandomPoses(m, 40, 3);
  const auto r = AnalyzeIdentifiability(m, qs, m.Nominal(), MeasurementKind::kFullPose);
  const Eigen::MatrixXd J = StackedJacobian(m, qs, m.Nominal(), MeasurementKind::kFullPose);
  // Each reported direction must be invisible to every pose: J·Δx ≈ 0 (checked on fresh poses).
  const auto fresh = RandomPoses(m, 20, 33);
  const Eigen::MatrixXd Jf = StackedJacobian(m, fresh, m.Nominal(), MeasurementKind::kFullPose);
  for (const auto& c : r.unidentifiable) {
    Eigen::VectorXd dx = Eigen::VectorXd::Zero(m.num_params());
    for (size_t i = 0; i < c.params.size(); ++i) dx(c.params[i]) = c.direction[i];
    EXPECT_LT((Jf * dx).norm(), 1e-9 * Jf.norm()) << c.explanation;
  }
  // The base columns alone have full column rank.
  Eigen::MatrixXd Jb(J.rows(), r.identifiable.size());
  for (size_t i = 0; i < r.identifiable.size(); ++i) Jb.col(i) = J.col(r.identifiable[i]);
  Eigen::FullPivLU<Eigen::MatrixXd> lu(Jb);
  EXPECT_EQ(lu.rank(), static_cast<int>(r.identifiable.size()));
  EXPECT_GT(r.condition_number, 1.0);
  EXPECT_LT(r.condition_number, 1e4);
}

TEST(Identifiability, SixDofBaseAndToolFrameGiveThirtyFor6R) {
  // A 6R arm with full 6-DoF base and tool frames: 4R + 2P + 6 = 30 identifiable (NOTES.md).
  ModelBuilder b("grb_frames");
  b.BaseFrame({0.1, 0.2, 0.3}, {0.01, 0.02, 0.03})
      .DhLink(0.150, -kPi / 2, 0.250, 0.0, Rev("j1"))
      .DhLink(0.570, -kPi, 0.0, -kPi / 2, Rev("j2"), /*hayati=*/true)
      .DhLink(0.150, kPi / 2, 0.0, 0.0, Rev("j3"))
      .DhLink(0.0, -kPi / 2, 0.645, 0.0, Rev("j4"))
      .DhLink(0.0, kPi / 2, 0.0, -kPi / 2, Rev("j5"))
      .DhLink(0.0, 0.0, -0.200, 0.0, Rev("j6"))
      .MarkerOffset({0.01, 0.02, 0.05})
      .ImuMounting({0.1, 0.2, 0.3});
  const KinematicModel m = b.Build();
  ASSERT_EQ(m.num_params(), 36);
  const auto qs = RandomPoses(m, 60, 4);
  const auto r = AnalyzeIdentifiability(m, qs, m.Nominal(), MeasurementKind::kFullPose);
  EXPECT_EQ(r.rank, 30) << AllExplanations(r);
  // Base z translation and rotation overlap d1 and θ1.
  EXPECT_TRUE(Explains(r, "d1")) << AllExplanations(r);
  EXPECT_TRUE(Explains(r, "theta1")) << AllExplanations(r);
}

}  // namespace
}  // namespace rcal::kinematics
