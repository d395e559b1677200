// `robocal report SESSION`: the calibration report page (results/report.html) from a session's
// results, with a short terminal summary and the JSON summary (--json).
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "stages/stages.hpp"

#include <fmt/core.h>

#include <memory>

namespace robocal::app {

CommandSpec report_command() {
  return {"report", "Write the calibration report page (HTML) of a session",
          [](CLI::App& cmd) -> CommandAction {
            auto session = std::make_shared<std::string>();
            auto json = std::make_shared<std::string>();
            cmd.footer(
                "Writes SESSION/results/report.html: one self-contained page (inline figures, no "
                "scripts, opens offline in any browser) with the accuracy before and after "
                "calibration on held-out poses (inside and outside the measured region), the "
                "error of each pose, the error histogram, error maps over the workspace (top and "
                "side views), the calibrated parameters with their 95 % intervals and strong "
                "correlations, what could not be identified, camera coverage and reprojection, "
                "residual diagnostics that flag error the model does not explain (residuals "
                "that change with position), and the time taken. `robocal demo` and `robocal "
                "batch` write it too.\n\n"
                "Needs results/identification.json from a successful `robocal identify`; "
                "without it the command names the missing file and exits with 3, leaving any "
                "existing page untouched. Held-out figures come from results/validation.json "
                "(`robocal validate`: against a simulated session's truth) and "
                "results/held_out.json (the wizard's validation step: held-out poses measured "
                "by the cameras); without either the page shows the fit on the measured poses "
                "and says so.");
            cmd.add_option("session", *session, "Session folder")->required();
            cmd.add_option("--json", *json, "Write the JSON summary here ('-' = stdout)");
            return [session, json]() {
              PipelineLog log;
              log.out = human_stream(*json);
              const auto summary = report_session(*session, log);
              if (!json->empty()) write_json(summary, *json);
              return exit_code_of(summary);
            };
          }};
}

}  // namespace robocal::app
