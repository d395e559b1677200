// `robocal batch --shard K/N` and `robocal batch-merge` in-process, on folders that are not
// sessions (each one fails at once, so the runs are cheap): which folders a shard takes (a
// partition of the list, balanced, whatever order it is given in), the merged summary against
// the unsharded run, and every refusal: bad --shard values (exit 2), and a missing or repeated
// shard, shards of another N or another folder list, malformed files (exit 3, naming the file).
#include "batch/batch_shard.hpp"
#include "cli/command_registry.hpp"
#include "run_robocal.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace {

using robocal::app::Shard;
using robocal::app::shard_positions;

using robocal::test::CliRun;
constexpr auto& run = robocal::test::run_robocal_captured;

nlohmann::json load(const std::string& path) {
  return nlohmann::json::parse(robocal::test::read_text(path));
}

void save(const nlohmann::json& doc, const std::string& path) {
  std::ofstream(path) << doc.dump(2);
}

// The summary without the seconds each session took (the one field that differs between runs).
nlohmann::json without_seconds(nlohmann::json doc) {
  for (auto& row : doc["sessions"]) row.erase("seconds");
  return doc;
}

TEST(BatchShardAssignment, PartitionOfTheListBalancedAndIndependentOfItsOrder) {
  std::mt19937 rng(19);
  std::uniform_int_distribution<int> letter('a', 'e');
  std::uniform_int_distribution<std::size_t> length(1, 3);  // 155 names possible
  for (int trial = 0; trial < 300; ++trial) {
    // Distinct names, some sharing prefixes ("ab", "abc"), in a random order.
    std::set<std::string> names;
    const int size = trial % 23;
    while (static_cast<int>(names.size()) < size) {
      std::string name(length(rng), 'x');
      for (char& c : name) c = static_cast<char>(letter(rng));
      names.insert("runs/" + name);
    }
    std::vector<std::string> list(names.begin(), names.end());
    std::shuffle(list.begin(), list.end(), rng);
    const int n = 1 + trial % 7;
    std::vector<int> times_taken(list.size(), 0);
    for (int k = 0; k < n; ++k) {
      const auto taken = shard_positions(list, Shard{k, n});
      // Sizes: floor or ceil of size/n.
      EXPECT_GE(static_cast<int>(taken.size()), size / n);
      EXPECT_LE(static_cast<int>(taken.size()), (size + n - 1) / n);
      // In the order given.
      EXPECT_TRUE(std::is_sorted(taken.begin(), taken.end()));
      std::set<std::string> slice;
      for (const auto p : taken) {
        ++times_taken[p];
        slice.insert(list[p]);
        // Brute force: the name's rank among all names (count of smaller ones) is K mod N.
        const auto rank = std::count_if(list.begin(), list.end(),
                                        [&](const std::string& s) { return s < list[p]; });
        EXPECT_EQ(rank % n, k) << list[p];
      }
      // Another order of the same list: the same slice.
      auto reordered = list;
      std::shuffle(reordered.begin(), reordered.end(), rng);
      std::set<std::string> again;
      for (const auto p : shard_positions(reordered, Shard{k, n})) again.insert(reordered[p]);
      EXPECT_EQ(again, slice) << "shard " << k << "/" << n;
    }
    for (const int t : times_taken) EXPECT_EQ(t, 1) << "every folder exactly once";
  }
}

TEST(BatchShardSyntax, ValidValuesAndTheWordsForBadOnes) {
  for (const char* ok : {"0/1", "0/2", "1/2", "3/4", "0/100"})
    EXPECT_EQ(robocal::app::shard_syntax_error(ok), "") << ok;
  const auto k_of_n = robocal::app::parse_shard("3/4");
  EXPECT_EQ(k_of_n.index, 3);
  EXPECT_EQ(k_of_n.count, 4);
  for (const char* bad :
       {"2/2", "3/2", "1/0", "0/0", "a/b", "1/", "/2", "-1/2", "+1/2", "1/2/3", " 1/2", "12", ""})
    EXPECT_NE(robocal::app::shard_syntax_error(bad), "") << "'" << bad << "'";
  EXPECT_NE(robocal::app::shard_syntax_error("2/2").find("counts from 0"), std::string::npos);
}

class BatchShards : public robocal::test::ScratchDirTest {
 protected:
  BatchShards() : ScratchDirTest("robocal_batch_shards_") {}
  // Folders that are not sessions: each is processed (and fails) at once.
  std::vector<std::string> folders(const std::vector<std::string>& names) const {
    std::vector<std::string> out;
    for (const auto& n : names) out.push_back(file(n));
    return out;
  }
  CliRun batch(const std::string& shard, const std::vector<std::string>& list,
               const std::string& json) const {
    std::vector<std::string> args = {"batch"};
    if (!shard.empty()) args.insert(args.end(), {"--shard", shard});
    args.insert(args.end(), list.begin(), list.end());
    args.insert(args.end(), {"--json", json});
    return run(args);
  }
  CliRun merge(const std::vector<std::string>& summaries, const std::string& json) const {
    std::vector<std::string> args = {"batch-merge"};
    args.insert(args.end(), summaries.begin(), summaries.end());
    args.insert(args.end(), {"--json", json});
    return run(args);
  }
};

TEST_F(BatchShards, BadShardValuesAreUsageErrorsNamingTheOption) {
  const auto list = folders({"a", "b"});
  for (const char* bad : {"0/0", "2/2", "3/2", "1/0", "a/b", "1", "-1/2"}) {
    const auto r = batch(bad, list, file("s.json"));
    EXPECT_EQ(r.code, robocal::app::kExitUsage) << bad;
    EXPECT_NE(r.err.find("--shard"), std::string::npos) << bad << ": " << r.err;
    EXPECT_NE(r.err.find(bad), std::string::npos) << bad << ": " << r.err;
  }
  EXPECT_FALSE(std::filesystem::exists(file("s.json"))) << "nothing processed";
  // A folder named twice would be processed by two shards at once.
  const auto twice = batch("0/2", {file("a"), file("b"), file("a")}, file("s.json"));
  EXPECT_EQ(twice.code, robocal::app::kExitUsage);
  EXPECT_NE(twice.err.find("same session folder"), std::string::npos) << twice.err;
  EXPECT_NE(twice.err.find(file("a")), std::string::npos) << twice.err;
}

// Without shards too: the same folder spelt three ways would be processed three times (with
// --jobs, at once) into one results/ folder. Refused before anything runs.
TEST_F(BatchShards, TheSameFolderNamedTwiceIsAUsageError) {
  std::filesystem::create_directories(file("s"));
  const auto r = batch("", {file("s"), file("s") + "/", file("s") + "/."}, file("s.json"));
  EXPECT_EQ(r.code, robocal::app::kExitUsage) << r.err;
  EXPECT_NE(r.err.find("same session folder"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(file("s.json"))) << "nothing processed";
}

TEST_F(BatchShards, MergedShardsAreTheUnshardedSummary) {
  // Given out of name order: the merge must give them back in this order.
  const auto list = folders({"d", "a", "e", "c", "b"});
  ASSERT_EQ(batch("", list, file("all.json")).code, robocal::app::kExitFailure);
  for (int k = 0; k < 3; ++k)
    ASSERT_EQ(batch(std::to_string(k) + "/3", list, file("s" + std::to_string(k) + ".json")).code,
              robocal::app::kExitFailure);

  // What shard 1 of 3 took: sorted a b c d e -> positions 1 and 4 -> b, e; in the order given.
  const auto s1 = load(file("s1.json"));
  EXPECT_EQ(s1["shard"]["index"], 1);
  EXPECT_EQ(s1["shard"]["count"], 3);
  EXPECT_EQ(s1["shard"]["folders_total"], 5);
  EXPECT_EQ(s1["shard"]["folders"].get<std::vector<std::string>>(), list);
  EXPECT_EQ(s1["shard"]["taken"].get<std::vector<std::string>>(),
            (std::vector<std::string>{file("e"), file("b")}));
  ASSERT_EQ(s1["sessions"].size(), 2U);
  EXPECT_EQ(s1["failed"], 2);

  // Any order of the summaries; exit code as batch's (every folder failed: 1).
  const auto m = merge({file("s2.json"), file("s0.json"), file("s1.json")}, file("merged.json"));
  EXPECT_EQ(m.code, robocal::app::kExitFailure) << m.err;
  const auto merged = load(file("merged.json"));
  const auto all = load(file("all.json"));
  EXPECT_EQ(without_seconds(merged), without_seconds(all));
  EXPECT_FALSE(merged.contains("shard"));
  std::vector<std::string> order;
  for (const auto& row : merged["sessions"]) order.push_back(row["session"]);
  EXPECT_EQ(order, list);
  EXPECT_EQ(merged["failed"], 5);
  EXPECT_EQ(merged["ok"], 0);

  // A shard given the folders in another order takes the same slice and merges alike.
  auto shuffled = list;
  std::reverse(shuffled.begin(), shuffled.end());
  ASSERT_EQ(batch("1/3", shuffled, file("s1r.json")).code, robocal::app::kExitFailure);
  EXPECT_EQ(merge({file("s0.json"), file("s1r.json"), file("s2.json")}, file("m2.json")).code,
            robocal::app::kExitFailure);
  EXPECT_EQ(without_seconds(load(file("m2.json"))), without_seconds(all));

  // One shard of one: the whole list.
  ASSERT_EQ(batch("0/1", list, file("one.json")).code, robocal::app::kExitFailure);
  EXPECT_EQ(merge({file("one.json")}, file("m1.json")).code, robocal::app::kExitFailure);
  EXPECT_EQ(without_seconds(load(file("m1.json"))), without_seconds(all));
}

TEST_F(BatchShards, MoreShardsThanFoldersLeavesEmptyShardsThatMerge) {
  const auto list = folders({"b", "a"});
  ASSERT_EQ(batch("", list, file("all.json")).code, robocal::app::kExitFailure);
  for (int k = 0; k < 4; ++k) batch(std::to_string(k) + "/4", list, file(std::to_string(k)));
  const auto empty = load(file("3"));
  EXPECT_EQ(empty["sessions"].size(), 0U);
  EXPECT_EQ(empty["failed"], 0);
  EXPECT_EQ(merge({file("0"), file("1"), file("2"), file("3")}, file("m.json")).code,
            robocal::app::kExitFailure);
  EXPECT_EQ(without_seconds(load(file("m.json"))), without_seconds(load(file("all.json"))));
}

TEST_F(BatchShards, MergeRefusesNamingTheFileAndTheProblem) {
  const auto list = folders({"a", "b", "c"});
  batch("0/2", list, file("s0.json"));
  batch("1/2", list, file("s1.json"));
  batch("1/3", list, file("t1.json"));                      // another N
  batch("1/2", folders({"a", "b", "w"}), file("u1.json"));  // another folder list
  batch("", list, file("all.json"));                        // not sharded
  std::filesystem::copy_file(file("s0.json"), file("s0_copy.json"));
  std::ofstream(file("broken.json")) << "{\"sessions\": [";
  auto cut = load(file("s0.json"));
  cut["sessions"].erase(1);  // a session lost
  save(cut, file("cut.json"));
  auto edited = load(file("s1.json"));
  edited["failed"] = 0;  // totals that do not count the sessions
  save(edited, file("edited.json"));

  struct Case {
    std::vector<std::string> files;
    std::string named;               // the file the message must name
    std::vector<std::string> words;  // and what it must say
  };
  const std::vector<Case> cases = {
      {{file("s0.json")}, file("s0.json"), {"shard 1/2 missing"}},
      {{file("s1.json")}, file("s1.json"), {"shard 0/2 missing"}},
      {{file("s0.json"), file("s1.json"), file("s0_copy.json")},
       file("s0_copy.json"),
       {"shard 0/2 again", file("s0.json")}},
      {{file("s0.json"), file("t1.json")}, file("t1.json"), {"split into 3", "split into 2"}},
      {{file("s0.json"), file("u1.json")}, file("u1.json"), {file("w"), "same folders"}},
      {{file("s0.json"), file("all.json")}, file("all.json"), {"without --shard"}},
      {{file("s0.json"), file("broken.json")}, file("broken.json"), {"not a JSON file"}},
      {{file("cut.json"), file("s1.json")}, file("cut.json"), {"not the 2 folders"}},
      {{file("s0.json"), file("edited.json")}, file("edited.json"), {"totals"}},
      {{file("s0.json"), file("nowhere.json")}, file("nowhere.json"), {}},
  };
  for (const auto& c : cases) {
    const auto r = merge(c.files, file("merged.json"));
    EXPECT_EQ(r.code, robocal::app::kExitBadInput) << c.named << ": " << r.err;
    EXPECT_NE(r.err.find(c.named), std::string::npos) << r.err;
    for (const auto& w : c.words)
      EXPECT_NE(r.err.find(w), std::string::npos) << w << " in " << r.err;
    EXPECT_FALSE(std::filesystem::exists(file("merged.json"))) << "nothing written: " << c.named;
  }
  // And what is right merges.
  EXPECT_EQ(merge({file("s1.json"), file("s0.json")}, file("merged.json")).code,
            robocal::app::kExitFailure);
}

}  // namespace
