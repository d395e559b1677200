// `robocal batch DIR...`: measure -> identify -> validate on several session folders, in
// parallel with --jobs. Every session is processed exactly as by the single commands (same
// functions, same files in its results/), so the results are the same as one by one.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "stages/stages.hpp"

#include "robocal/core/parallel.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <mutex>

namespace robocal::app {

namespace {

struct BatchOptions {
  std::vector<std::string> sessions;
  int jobs = 1;
  int threads = 2;
  int held_out = 500;
  std::string json;
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

std::string um(const nlohmann::json& row, const char* key) {
  return row.contains(key) ? fmt::format("{:.1f}", row[key].get<double>() * 1e6) : "-";
}

int run_batch(const BatchOptions& o) {
  std::FILE* out = human_stream(o.json);
  const int n = static_cast<int>(o.sessions.size());
  std::vector<nlohmann::json> rows(o.sessions.size());
  std::mutex print_mutex;
  // Sessions in parallel run silently with one thread each; a single job keeps progress output.
  const int jobs = std::clamp(o.jobs, 1, n);
  core::parallel_for(n, jobs, [&](int i) {
    const auto k = static_cast<std::size_t>(i);
    PipelineLog log;
    log.out = jobs == 1 ? out : nullptr;
    log.threads = jobs == 1 ? o.threads : 1;
    if (jobs == 1) fmt::print(out, "\n--- {}\n", o.sessions[k]);
    rows[k] = process(o.sessions[k], o, log);
    const std::lock_guard<std::mutex> lock(print_mutex);
    const auto& r = rows[k];
    const std::string why = r.contains("error")    ? r["error"].get<std::string>()
                            : r.contains("reason") ? r["reason"].get<std::string>()
                                                   : "";
    fmt::print(out, "{}: {}{}\n", o.sessions[k], r["status"].get<std::string>(),
               why.empty() ? "" : " (" + why + ")");
    std::fflush(out);
  });

  fmt::print(out, "\n{:<40} {:>6} {:>10} {:>12} {:>14} {:>9}\n", "session", "poses", "identify",
             "nominal µm", "calibrated µm", "seconds");
  int failed = 0;
  for (const auto& r : rows) {
    fmt::print(out, "{:<40} {:>6} {:>10} {:>12} {:>14} {:>9.1f}\n", r["session"].get<std::string>(),
               fmt::format("{}/{}", r.value("poses_used", 0), r.value("poses_total", 0)),
               r.value("identify", r.contains("error") ? "error" : "-"), um(r, "nominal_rms_m"),
               um(r, "calibrated_rms_m"), r["seconds"].get<double>());
    failed += r["status"] == "ok" ? 0 : 1;
  }
  fmt::print(out, "{} of {} sessions ok\n", n - failed, n);
  const nlohmann::json doc{{"sessions", rows}, {"ok", n - failed}, {"failed", failed}};
  if (!o.json.empty()) write_json(doc, o.json);
  return failed == 0 ? kExitOk : kExitFailure;
}

}  // namespace

CommandSpec batch_command() {
  return {"batch", "Process recorded session folders end to end (measure, identify, validate)",
          [](CLI::App& cmd) -> CommandAction {
            auto o = std::make_shared<BatchOptions>();
            cmd.footer(
                "Runs `robocal measure`, `identify` and `validate` on each SESSION folder "
                "(app/SESSION.md), --jobs of them at a time; each session's results/ get exactly "
                "what the single commands write. A session with bad input is reported and the "
                "others go on. Sessions without truth/ (recorded ones) are not validated. Prints "
                "a summary table; --json writes it as JSON. Exit code 1 when any session "
                "failed.");
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
            return [o]() { return run_batch(*o); };
          }};
}

}  // namespace robocal::app
