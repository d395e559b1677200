// `robocal validate SESSION`: the calibrated robot against a simulated session's hidden truth.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "session/json_values.hpp"
#include "session/results_layout.hpp"
#include "stages/stages.hpp"
#include "summary/validation_summary.hpp"

#include <fmt/core.h>

#include <memory>

namespace robocal::app {

CommandSpec validate_command() {
  return {"validate", "Compare the calibrated robot of a simulated session with its hidden truth",
          [](CLI::App& cmd) -> CommandAction {
            auto session = std::make_shared<std::string>();
            auto json = std::make_shared<std::string>();
            auto held_out = std::make_shared<int>(500);
            cmd.footer(
                "Reads SESSION/truth/ (written by `robocal simulate`; the only stage that does) "
                "and results/identification.json, then compares the nominal model (with its base "
                "frame fitted to the measurements) and the calibrated model with the true robot "
                "at --held-out random reachable actuator configurations the fit never used: "
                "position error RMS / max in the camera frame, and after a best-fit rigid "
                "registration (the robot's accuracy in its own frame); the absolute figures also "
                "split into "
                "configurations inside the measured region (the convex hull of the measured "
                "board positions: interpolation) and outside it (extrapolation), with each worst "
                "configuration's distance to that region. Also the calibrated "
                "cameras, the rig baseline and the measured board poses against the truth, and "
                "each parameter's estimated vs true change. Writes results/validation.json.\n\n"
                "A recorded session has no truth/: validate says so and exits with 3.");
            cmd.add_option("session", *session, "Session folder")->required();
            cmd.add_option("--held-out", *held_out, "Held-out configurations")
                ->check(CLI::Range(10, 100000))
                ->capture_default_str();
            cmd.add_option("--json", *json, "Write the JSON report here ('-' = stdout)");
            return [session, json, held_out]() {
              PipelineLog log;
              log.out = human_stream(*json);
              const auto report = validate_session(*session, *held_out, log);
              if (report.value("status", "") == "no_truth") {
                fmt::print(stderr, "error: {}\n", report.value("message", ""));
              } else {
                const auto ident = read_json_file(ResultsLayout{*session}.identification(),
                                                  "run `robocal identify` on the session first");
                print_validation_summary(log.out, report, ident);
              }
              if (!json->empty()) write_json(report, *json);
              return exit_code_of(report);
            };
          }};
}

}  // namespace robocal::app
