// A checkpoint written as text and restored continues exactly as the uninterrupted identifier.
#include <gtest/gtest.h>

#include <filesystem>

#include "fixture.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/checkpoint_json.hpp"

namespace rcal::transport {
namespace {

using testing::Grb3016;

TEST(Checkpoint, RestoredIdentifierContinuesBitForBit) {
  const Grb3016 g(30);
  identification::EkfIdentifier whole(g.model, g.base), first(g.model, g.base);
  for (int k = 0; k < 15; ++k) {
    whole.Update(g.poses[k]);
    first.Update(g.poses[k]);
  }
  CheckpointFile f{ModelId(g.model), 1234, 14, first.Checkpoint()};
  const auto dir = std::filesystem::temp_directory_path() / "rcal_checkpoint_test";
  std::filesystem::remove_all(dir);
  SaveCheckpoint(dir / "ekf.json", f);
  const CheckpointFile back = LoadCheckpoint(dir / "ekf.json");
  EXPECT_EQ(back.model_id, f.model_id);
  EXPECT_EQ(back.utime, 1234);
  EXPECT_EQ(back.last_pose_index, 14);

  identification::EkfIdentifier resumed(g.model, g.base);
  resumed.Restore(back.checkpoint);
  EXPECT_EQ(resumed.x(), first.x());
  EXPECT_EQ(resumed.P(), first.P());
  EXPECT_EQ(resumed.accepted(), first.accepted());
  for (int k = 15; k < 30; ++k) {
    whole.Update(g.poses[k]);
    resumed.Update(g.poses[k]);
  }
  EXPECT_EQ(resumed.x(), whole.x());
  EXPECT_EQ(resumed.P(), whole.P());
  EXPECT_EQ(resumed.relinearizations(), whole.relinearizations());
  std::filesystem::remove_all(dir);
}

TEST(Checkpoint, MalformedTextIsAnErrorNamingTheKey) {
  EXPECT_THROW(ParseCheckpoint("not json"), std::runtime_error);
  try {
    ParseCheckpoint(R"({"schema": "rcal.ekf_checkpoint/1", "model_id": "m", "utime": 0,
                        "last_pose_index": 0})");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("x0"), std::string::npos) << e.what();
  }
  try {
    ParseCheckpoint(R"({"schema": "other/1"})");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("schema"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace rcal::transport
