// `robocal batch DIR...`: measure -> identify -> validate on several session folders, in
// parallel with --jobs. Every session is processed exactly as by the single commands (same
// functions, same files in its results/), so the results are the same as one by one. With
// --shard K/N only the K-th of N slices of the list (batch/batch_shard.hpp); `robocal
// batch-merge` puts the shards' summaries back together.
#include "batch/batch_shard.hpp"
#include "batch/batch_summary.hpp"
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "stages/stages.hpp"

#include "robocal/core/parallel.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

struct BatchOptions {
  std::vector<std::string> sessions;
  int jobs = 1;
  int threads = 2;
  int held_out = 500;
  std::string json;
  std::string shard;  // "K/N", empty: the whole list
};

// One session end to end; bad input becomes an "error" entry, never stops the batch.
nlohmann::json process(const std::string& dir, const BatchOptions& o, const PipelineLog& log) {
  const auto start = std::chrono::steady_clock::now();
  nlohmann::json row{{"session", dir}};
  try {
    const auto measure = measure_session(dir, "", log);
    row["measure"] = measure.value("status", "failed");
    row["poses_used"] = measure.contains("poses") ? measure["poses"].value("used", 0) : 0;
    row["poses_total"] = measure.contains("poses") ? measure["poses"].value("total", 0) : 0;
    if (measure.value("status", "") != "ok") row["reason"] = measure.value("message", "");
    if (measure.value("status", "") == "ok") {
      const auto ident = identify_session(dir, "", log);
      row["identify"] = ident.value("status", "failed");
      if (ident.contains("result")) {
        row["fit_residual_rms_m"] = ident["result"]["residuals"]["position_rms_m"];
        // As identify counts them: the parameters the solve estimated.
        int estimated = 0;
        for (const auto& p : ident["result"].value("parameters", nlohmann::json::array()))
          estimated += p.value("estimated", false) ? 1 : 0;
        row["estimated_parameters"] = estimated;
      }
      if (ident.value("status", "") != "ok") row["reason"] = ident.value("message", "");
      if (ident.value("status", "") == "ok") {
        const auto v = validate_session(dir, o.held_out, log);
        row["validate"] = v.value("status", "failed");
        if (v.value("status", "") == "ok") {
          row["nominal_rms_m"] = v["nominal"]["rms_m"];
          row["calibrated_rms_m"] = v["calibrated"]["rms_m"];
          row["calibrated_registered_rms_m"] = v["calibrated_registered"]["rms_m"];
          row["held_out_poses"] = v["held_out_poses"];
        }
      }
      // Each identified session gets its page (results/report.html), validated or not.
      if (ident.value("status", "") == "ok") {
        const auto page = report_session(dir, PipelineLog{nullptr});
        row["report"] = page.value("page", "");
      }
    }
  } catch (const InputError& e) {
    row["error"] = e.what();
  } catch (const fs::filesystem_error& e) {
    // A folder the system refuses (a symbolic link loop, no permission): the session's input, as
    // `robocal measure` says it (exit 3 there), not a robocal bug.
    row["error"] = filesystem_problem(e);
  } catch (const std::exception& e) {
    // Anything else stays with its session too: the other sessions of the batch go on.
    row["error"] = std::string("internal error (please report it): ") + e.what();
  }
  const bool ok = !row.contains("error") && row.value("measure", "") == "ok" &&
                  row.value("identify", "") == "ok" &&
                  (row.value("validate", "") == "ok" || row.value("validate", "") == "no_truth");
  row["status"] = ok ? "ok" : "failed";
  row["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return row;
}

int run_batch(const BatchOptions& o) {
  std::FILE* out = human_stream(o.json);
  // The folders this run processes: the whole list, or this shard's slice of it.
  std::vector<std::string> sessions = o.sessions;
  nlohmann::json shard_doc;
  // A folder named twice (also as `s/`, `./s` or through a link) would be processed twice, with
  // --jobs at the same time, into one results/ folder.
  std::map<std::string, std::string> seen;  // canonical path -> as given
  for (const auto& dir : o.sessions) {
    std::error_code ec;
    const fs::path canonical = fs::weakly_canonical(fs::path(dir), ec);
    const std::string key = ec ? dir : canonical.string();
    const auto [it, first] = seen.emplace(key, dir);
    if (!first) {
      fmt::print(stderr,
                 "batch: '{}' and '{}' are the same session folder; name each session once\n",
                 it->second, dir);
      return kExitUsage;
    }
  }
  if (!o.shard.empty()) {
    const Shard shard = parse_shard(o.shard);  // CLI11 checked the syntax
    const auto taken = shard_positions(o.sessions, shard);
    sessions.clear();
    for (const std::size_t p : taken) sessions.push_back(o.sessions[p]);
    shard_doc = shard_section(o.sessions, shard, taken);
    fmt::print(
        out,
        "shard {}/{}: {} of {} folders (positions {}, {}, {}, ... of the list sorted by name)\n",
        shard.index, shard.count, sessions.size(), o.sessions.size(), shard.index,
        shard.index + shard.count, shard.index + 2 * shard.count);
  }
  const int n = static_cast<int>(sessions.size());
  std::vector<nlohmann::json> rows(sessions.size());
  std::mutex print_mutex;
  // Sessions in parallel run silently with one thread each; a single job keeps progress output.
  const int jobs = std::clamp(o.jobs, 1, std::max(n, 1));
  core::parallel_for(n, jobs, [&](int i) {
    const auto k = static_cast<std::size_t>(i);
    PipelineLog log;
    log.out = jobs == 1 ? out : nullptr;
    log.threads = jobs == 1 ? o.threads : 1;
    if (jobs == 1) fmt::print(out, "\n--- {}\n", sessions[k]);
    rows[k] = process(sessions[k], o, log);
    const std::lock_guard<std::mutex> lock(print_mutex);
    const auto& r = rows[k];
    const std::string why = r.contains("error")    ? r["error"].get<std::string>()
                            : r.contains("reason") ? r["reason"].get<std::string>()
                                                   : "";
    fmt::print(out, "{}: {}{}\n", sessions[k], r["status"].get<std::string>(),
               why.empty() ? "" : " (" + why + ")");
    std::fflush(out);
  });

  print_batch_table(out, rows);
  nlohmann::json doc = batch_summary(rows);
  if (!shard_doc.is_null()) doc["shard"] = shard_doc;
  if (!o.json.empty()) write_json(doc, o.json);
  return batch_exit_code(doc);
}

}  // namespace

CommandSpec batch_command() {
  return {
      "batch", "Process recorded session folders end to end (measure, identify, validate)",
      [](CLI::App& cmd) -> CommandAction {
        auto o = std::make_shared<BatchOptions>();
        cmd.footer(
            "Runs `robocal measure`, `identify` and `validate` on each SESSION folder "
            "(app/SESSION.md), --jobs of them at a time; each session's results/ get exactly "
            "what the single commands write. A session with bad input is reported and the "
            "others go on. Sessions without truth/ (recorded ones) are not validated. Prints "
            "a summary table; --json writes it as JSON. Exit code 1 when any session "
            "failed.\n\n"
            "Examples:\n"
            "  robocal batch runs/* --jobs 2 --json summary.json\n"
            "  robocal batch runs/* --shard 0/2 --json shard-0.json   # one machine\n"
            "  robocal batch runs/* --shard 1/2 --json shard-1.json   # another one\n"
            "  robocal batch-merge shard-0.json shard-1.json --json summary.json\n\n"
            "--shard K/N processes the folders at positions K, K+N, K+2N, ... of the list "
            "sorted by name, so every shard takes the same slice whatever order the folders "
            "are given in, and the N shards together take each folder once. K counts from 0, "
            "like Kubernetes' JOB_COMPLETION_INDEX and Slurm's SLURM_ARRAY_TASK_ID with "
            "--array=0-(N-1): --shard \"$SLURM_ARRAY_TASK_ID/N\". Give every shard the same "
            "folder list. The shard's --json summary records K, N, the whole list and the "
            "folders it took; `robocal batch-merge` combines the N summaries into the one "
            "this batch would write without --shard.");
        cmd.add_option("sessions", o->sessions, "Session folders")->required();
        cmd.add_option("--jobs,-j", o->jobs, "Sessions processed in parallel")
            ->check(CLI::Range(1, 64))
            ->capture_default_str();
        cmd.add_option("--threads", o->threads, "Detection threads with --jobs 1")
            ->check(CLI::Range(1, 64))
            ->capture_default_str();
        cmd.add_option("--held-out", o->held_out, "Held-out configurations for validate")
            ->check(CLI::Range(10, 100000))
            ->capture_default_str();
        cmd.add_option("--json", o->json, "Write the summary JSON here ('-' = stdout)");
        cmd.add_option("--shard", o->shard,
                       "Process only slice K of N of the folder list (K from 0), e.g. 0/4")
            ->type_name("K/N")
            ->check(CLI::Validator([](std::string& text) { return shard_syntax_error(text); }, ""));
        return [o]() { return run_batch(*o); };
      }};
}

}  // namespace robocal::app
