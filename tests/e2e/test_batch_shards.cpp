// scripts/batch-shards.sh (two `robocal batch --shard K/2` processes, then `robocal batch-merge`)
// on a rendered session, a folder that is not a session and one that does not exist: the merged
// summary equals the unsharded batch's on the same folders (sessions, order, statuses, figures,
// totals, exit code). One real session keeps the test short; tests/unit/app/test_batch_shards.cpp
// covers the slices and the refusals.
#include "session_test_support.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using robocal::test::read_file;
using robocal::test::run_cli;

fs::path scratch(const std::string& name) {
  const auto dir = fs::temp_directory_path() / ("robocal_e2e_shards_" + name);
  fs::remove_all(dir);
  return dir;
}

std::string quoted(const std::string& s) {
  return "'" + s + "'";
}

nlohmann::json without_seconds(nlohmann::json doc) {
  for (auto& row : doc["sessions"]) row.erase("seconds");
  return doc;
}

TEST(BatchShardsEndToEnd, ScriptRunsTwoShardsAndItsMergeEqualsTheUnshardedBatch) {
  const fs::path a = scratch("a_sim"), c = scratch("c_not_a_session"), d = scratch("d_missing");
  ASSERT_EQ(run_cli({"simulate", "--quick", "--poses", "24", "--seed", "3", "--out", a.string()}),
            0);
  fs::create_directories(c);
  // Not in name order: sorted a, c, d -> shard 0/2 takes a and d, shard 1/2 takes c.
  const std::vector<std::string> given = {d.string(), c.string(), a.string()};

  const fs::path work = scratch("work");
  const fs::path merged_path = scratch("merged.json");
  std::string command = "ROBOCAL=" + quoted(ROBOCAL_BINARY) + " bash " +
                        quoted(std::string(ROBOCAL_SOURCE_DIR) + "/scripts/batch-shards.sh") +
                        " -n 2 -w " + quoted(work.string()) + " -a --held-out -a 200 " +
                        quoted(merged_path.string());
  for (const auto& dir : given) command += " " + quoted(dir);
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status)) << command;
  // One folder failed: exit code 1, as batch's.
  EXPECT_EQ(WEXITSTATUS(status), 1) << command;

  const auto shard0 = nlohmann::json::parse(read_file(work / "shard-0.json"));
  const auto shard1 = nlohmann::json::parse(read_file(work / "shard-1.json"));
  EXPECT_EQ(shard0["shard"]["taken"].get<std::vector<std::string>>(),
            (std::vector<std::string>{d.string(), a.string()}));
  EXPECT_EQ(shard1["shard"]["taken"].get<std::vector<std::string>>(),
            (std::vector<std::string>{c.string()}));
  for (const auto& s : {shard0, shard1}) {
    EXPECT_EQ(s["shard"]["count"], 2);
    EXPECT_EQ(s["shard"]["folders_total"], 3);
  }
  const auto merged = nlohmann::json::parse(read_file(merged_path));

  // The same folders from scratch, unsharded.
  fs::remove_all(a / "results");
  const fs::path whole_path = scratch("whole.json");
  std::vector<std::string> args = {"batch", "--held-out", "200", "--json", whole_path.string()};
  args.insert(args.end(), given.begin(), given.end());
  EXPECT_EQ(run_cli(args), 1);
  const auto whole = nlohmann::json::parse(read_file(whole_path));

  EXPECT_EQ(without_seconds(merged), without_seconds(whole));
  // What that equality covers, spelled out.
  ASSERT_EQ(merged["sessions"].size(), 3U);
  std::vector<std::string> order;
  for (const auto& row : merged["sessions"]) order.push_back(row["session"]);
  EXPECT_EQ(order, given);
  for (int i : {0, 1}) {
    const auto& row = merged["sessions"][static_cast<std::size_t>(i)];
    EXPECT_EQ(row["status"], "failed") << row.dump();
    EXPECT_TRUE(row.contains("error")) << row.dump();
  }
  const auto& row = merged["sessions"][2];
  EXPECT_EQ(row["status"], "ok") << row.dump();
  EXPECT_GT(row["held_out_poses"].get<int>(), 100);
  // Figures against the simulator's truth: millimetres off nominally, far better calibrated.
  EXPECT_GT(row["nominal_rms_m"].get<double>(), 5e-4);
  EXPECT_LT(row["calibrated_rms_m"].get<double>(), row["nominal_rms_m"].get<double>() / 10);
  EXPECT_EQ(row["calibrated_rms_m"], whole["sessions"][2]["calibrated_rms_m"]);
  EXPECT_EQ(merged["ok"], 1);
  EXPECT_EQ(merged["failed"], 2);
  EXPECT_FALSE(merged.contains("shard"));
}

}  // namespace
