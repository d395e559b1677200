// `robocal batch-merge SUMMARY.json...`: the --json summaries of `robocal batch --shard K/N`
// runs (one per shard, any order) -> the summary the whole batch writes without --shard.
#include "batch/batch_shard.hpp"
#include "batch/batch_summary.hpp"
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "stages/stages.hpp"

#include <fmt/core.h>

#include <memory>

namespace robocal::app {

namespace {

struct MergeOptions {
  std::vector<std::string> summaries;
  std::string json;
};

int run_merge(const MergeOptions& o) {
  std::FILE* out = human_stream(o.json);
  std::vector<ShardSummary> shards;
  shards.reserve(o.summaries.size());
  for (const auto& path : o.summaries) shards.push_back(read_shard_summary(path));
  const nlohmann::json merged = merge_shard_summaries(shards);
  fmt::print(out, "merged {} shard summaries: {} sessions\n", shards.size(),
             merged["sessions"].size());
  print_batch_table(out, merged["sessions"].get<std::vector<nlohmann::json>>());
  if (!o.json.empty()) write_json(merged, o.json);
  return batch_exit_code(merged);
}

}  // namespace

CommandSpec batch_merge_command() {
  return {"batch-merge", "Combine the JSON summaries of `robocal batch --shard K/N` runs into one",
          [](CLI::App& cmd) -> CommandAction {
            auto o = std::make_shared<MergeOptions>();
            cmd.footer(
                "Takes the --json summaries of the N shards of one `robocal batch --shard K/N` "
                "split, in any order, and writes the summary `robocal batch` writes on the whole "
                "folder list: the same fields and totals, the sessions in the order the folders "
                "were given. Prints the batch table. Exit code 0 when every session is ok, 1 when "
                "any failed (as batch); 3, naming the file and the problem, for a file that is "
                "not a shard summary, a shard given twice, a missing shard, or shards of "
                "different N or different folder lists.\n\n"
                "Examples:\n"
                "  robocal batch-merge shard-0.json shard-1.json --json summary.json\n"
                "  robocal batch-merge shards/*.json --json -      # merged JSON on stdout");
            cmd.add_option("summaries", o->summaries, "The shards' summary files (batch --json)")
                ->required();
            cmd.add_option("--json", o->json, "Write the merged summary JSON here ('-' = stdout)");
            return [o]() { return run_merge(*o); };
          }};
}

}  // namespace robocal::app
