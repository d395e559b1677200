#pragma once
// `robocal batch --shard K/N` and `robocal batch-merge`: a long folder list split over N
// processes (a Slurm job array, a Kubernetes indexed Job) and their summaries put back together.
//
// Which folders shard K takes: the folder list sorted by its bytes (std::string order: no locale,
// so every node of a cluster sorts alike), then the folders at sorted positions K, K+N, K+2N, ...
// So the slices do not depend on the order the folders are given in (a shell glob sorts by the
// node's locale), they never overlap, together they are the whole list, and their sizes differ
// by one at most. (A hash of the name would keep a folder's shard when the list grows, but the
// shards of one batch are run on one list, and a hash can leave a shard with twice its share.)
// K counts from 0, as JOB_COMPLETION_INDEX does and as SLURM_ARRAY_TASK_ID does with
// --array=0-(N-1).
#include <nlohmann/json.hpp>

#include <cstddef>
#include <string>
#include <vector>

namespace robocal::app {

struct Shard {
  int index = 0;  // K: 0 .. count-1
  int count = 1;  // N
};

// The problem with a --shard value in words, or "" when it is a valid K/N.
std::string shard_syntax_error(const std::string& text);

// Parses K/N; throws std::invalid_argument with shard_syntax_error's words when it is not valid.
Shard parse_shard(const std::string& text);

// Positions in `folders` (ascending, so in the order given) of the folders shard `s` takes.
std::vector<std::size_t> shard_positions(const std::vector<std::string>& folders, Shard s);

// The "shard" section of a shard's summary: K, N, the rule, the whole folder list as given, its
// size and the folders this shard took.
nlohmann::json shard_section(const std::vector<std::string>& folders, Shard s,
                             const std::vector<std::size_t>& taken);

// A shard's summary as read from its file.
struct ShardSummary {
  std::string path;
  nlohmann::json doc;
};

// Reads a summary file; InputError naming the file when it cannot be read or is not JSON.
ShardSummary read_shard_summary(const std::string& path);

// The summaries of shards 0..N-1 of one folder list (in any order) -> the summary an unsharded
// `robocal batch` on that list writes: the same fields and totals, the sessions in the order the
// folders were given (to shard 0). InputError naming the file and the problem for a file that is
// not a shard summary, a shard given twice, a missing shard, shards of different N or of
// different folder lists.
nlohmann::json merge_shard_summaries(const std::vector<ShardSummary>& shards);

}  // namespace robocal::app
