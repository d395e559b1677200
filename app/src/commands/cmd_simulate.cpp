// `robocal simulate --out DIR`: writes a synthetic session folder (app/SESSION.md) with rendered
// images, actuator readings and the hidden truth in DIR/truth/.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "stages/stages.hpp"

#include <fmt/format.h>

#include <memory>

namespace robocal::app {

CommandSpec simulate_command() {
  return {"simulate", "Write a synthetic session folder: rendered images of a simulated cell",
          [](CLI::App& cmd) -> CommandAction {
            auto o = std::make_shared<SimulateOptions>();
            auto json = std::make_shared<std::string>();
            auto threads = std::make_shared<int>(2);
            auto out = std::make_shared<std::string>();
            auto read_noise = std::make_shared<double>(0.0);
            cmd.footer(
                "A library robot gets a hidden \"true\" geometry (its drawing plus random "
                "tolerances: lengths sigma 0.5 mm, angles 0.2 deg, from --seed). Two cameras "
                "(1600x1200, or 1280x960 with --quick) are placed by the planner to see the "
                "board over the working volume (below it for the Delta); where one pair sees "
                "the board at under a quarter of the reachable poses of a robot with loops (the "
                "Gantry-Tau), an array of up "
                "to 6 cameras in pairs, any two of which measure a pose. The folder gets what a "
                "real cell would record: calibration-board views for each camera's intrinsics "
                "and for the stereo rig, and --poses robot poses (planned by observability among "
                "those where both cameras (two of an array) see the end-effector board; random "
                "ones with "
                "--random-poses) with one image "
                "per camera and the actuator readings (noise 2e-6, quantised to 1e-6). The truth "
                "goes to DIR/truth/, which only `robocal validate` reads.\n\n"
                "Next: robocal measure DIR && robocal identify DIR && robocal validate DIR "
                "(or robocal batch DIR). Format: app/SESSION.md.");
            cmd.add_option("--out", *out, "New session folder (must not exist or be empty)")
                ->required();
            cmd.add_option("--robot", o->robot, "Library robot name or robot file")
                ->capture_default_str();
            cmd.add_option("--seed", o->seed, "Random seed (same seed, same session)")
                ->capture_default_str();
            cmd.add_option("--poses", o->poses, "Robot poses to record")
                ->check(CLI::Range(3, 1000))
                ->capture_default_str();
            cmd.add_option(
                "--intrinsic-views", o->intrinsic_views,
                fmt::format("Calibration-board views per camera (default {}, 12 with --quick)",
                            SimulateOptions{}.intrinsic_views));
            cmd.add_option("--rig-views", o->rig_views,
                           fmt::format("Board views both cameras see (default {}, 6 with --quick)",
                                       SimulateOptions{}.rig_views));
            cmd.add_flag("--random-poses", o->random_poses,
                         "Random reachable poses with the board in view (for comparison) "
                         "instead of poses planned by observability (planner/)");
            cmd.add_flag("--idealised-truth", o->idealised_truth,
                         "The true robot differs from its drawing only where the model can follow "
                         "(default: also where it cannot, as a real robot does)");
            cmd.add_flag("--quick", o->quick, "Smaller images and fewer views (for CI)");
            cmd.add_option("--read-noise", *read_noise,
                           "Sensor read noise, grey levels (default 2; low values give small "
                           "PNG files, e.g. for test data)")
                ->check(CLI::Range(0.0, 50.0));
            cmd.add_option("--threads", *threads, "Rendering threads")
                ->check(CLI::Range(1, 64))
                ->capture_default_str();
            cmd.add_option("--json", *json, "Write the JSON report here ('-' = stdout)");
            return [o, json, threads, out, read_noise, &cmd]() {
              if (o->quick) {
                if (cmd.count("--intrinsic-views") == 0) o->intrinsic_views = 12;
                if (cmd.count("--rig-views") == 0) o->rig_views = 6;
              }
              if (cmd.count("--read-noise") > 0) o->read_noise = *read_noise;
              o->out = *out;
              PipelineLog log;
              log.out = human_stream(*json);
              log.threads = *threads;
              const auto report = simulate_session(*o, log);
              if (!json->empty()) write_json(report, *json);
              return exit_code_of(report);
            };
          }};
}

}  // namespace robocal::app
