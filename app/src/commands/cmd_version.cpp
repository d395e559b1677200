#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "robocal_version.hpp"

#include <fmt/core.h>
#include <Eigen/Core>

namespace robocal::app {

// `robocal version`: the version and the library versions it was built against, as JSON with
// --json, so a session folder or a bug report can record exactly what produced it.
CommandSpec version_command() {
  return {"version", "Print robocal's version and the versions of the libraries it uses",
          [](CLI::App& cmd) -> CommandAction {
            auto json = std::make_shared<bool>(false);
            cmd.add_flag("--json", *json, "Print machine-readable JSON");
            return [json]() {
              nlohmann::json doc = {
                  {"robocal", kVersion},
                  {"eigen", fmt::format("{}.{}.{}", EIGEN_WORLD_VERSION, EIGEN_MAJOR_VERSION,
                                        EIGEN_MINOR_VERSION)},
                  {"compiler", fmt::format("GCC {}.{}", __GNUC__, __GNUC_MINOR__)},
              };
              if (*json) {
                write_json(doc, "-");
              } else {
                for (const auto& [key, value] : doc.items())
                  fmt::print("{:<10} {}\n", key, value.get<std::string>());
              }
              return int{kExitOk};
            };
          }};
}

}  // namespace robocal::app
