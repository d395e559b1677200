#include "batch/batch_summary.hpp"

#include "cli/command_registry.hpp"

#include <fmt/core.h>

#include <string>

namespace robocal::app {

namespace {

std::string um(const nlohmann::json& row, const char* key) {
  return row.contains(key) ? fmt::format("{:.1f}", row[key].get<double>() * 1e6) : "-";
}

}  // namespace

nlohmann::json batch_summary(const std::vector<nlohmann::json>& rows) {
  int failed = 0;
  for (const auto& r : rows) failed += r.value("status", "") == "ok" ? 0 : 1;
  const int n = static_cast<int>(rows.size());
  return nlohmann::json{{"sessions", rows}, {"ok", n - failed}, {"failed", failed}};
}

void print_batch_table(std::FILE* out, const std::vector<nlohmann::json>& rows) {
  fmt::print(out, "\n{:<40} {:>6} {:>10} {:>12} {:>14} {:>9}\n", "session", "poses", "identify",
             "nominal µm", "calibrated µm", "seconds");
  int failed = 0;
  for (const auto& r : rows) {
    fmt::print(out, "{:<40} {:>6} {:>10} {:>12} {:>14} {:>9.1f}\n", r["session"].get<std::string>(),
               fmt::format("{}/{}", r.value("poses_used", 0), r.value("poses_total", 0)),
               r.value("identify", r.contains("error") ? "error" : "-"), um(r, "nominal_rms_m"),
               um(r, "calibrated_rms_m"), r.value("seconds", 0.0));
    failed += r.value("status", "") == "ok" ? 0 : 1;
  }
  const int n = static_cast<int>(rows.size());
  fmt::print(out, "{} of {} sessions ok\n", n - failed, n);
}

int batch_exit_code(const nlohmann::json& summary) {
  return summary.value("failed", 0) == 0 ? kExitOk : kExitFailure;
}

}  // namespace robocal::app
