#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"

#include "robocal/vision/target_io.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

namespace robocal::app {

namespace {

// A target that no printer takes, or a drawing too large to open, is almost always a typo in
// cols/rows or the square size: say so instead of silently writing it.
template <typename Args>
std::vector<std::string> print_warnings(const vision::TargetBoard& board,
                                        const Eigen::Vector2d& size, const Args& a) {
  std::vector<std::string> w;
  constexpr double kA0Long = 1.189;  // m
  constexpr double kA0Short = 0.841;
  if (std::max(size.x(), size.y()) > kA0Long || std::min(size.x(), size.y()) > kA0Short)
    w.push_back(fmt::format(
        "the paper is {:.0f} x {:.0f} mm, larger than A0 (841 x 1189 mm): check cols, rows and "
        "the square size in {}",
        size.x() * 1000, size.y() * 1000, a.target));
  for (const std::string& file : {a.svg, a.pdf}) {
    std::error_code ec;
    if (file.empty()) continue;
    const auto bytes = std::filesystem::file_size(file, ec);
    if (!ec && bytes > 5'000'000)
      w.push_back(fmt::format(
          "{} is {:.1f} MB ({} corners, {} markers): large drawings are slow "
          "to open and print",
          file, static_cast<double>(bytes) / 1e6, board.corners.size(), board.markers.size()));
  }
  return w;
}

}  // namespace

// `robocal target board.yaml --svg board.svg [--pdf board.pdf]`: checks a target file and writes
// a true-scale drawing to print.
CommandSpec target_command() {
  return {"target", "Check a target file and write a true-scale SVG/PDF to print",
          [](CLI::App& cmd) -> CommandAction {
            struct Args {
              std::string target, svg, pdf;
              bool json = false;
            };
            auto a = std::make_shared<Args>();
            cmd.add_option("target", a->target,
                           "Target file (YAML: apriltag_grid, chessboard, charuco)")
                ->required();
            cmd.add_option("--svg", a->svg, "Write the drawing as SVG (millimetres, 1:1)");
            cmd.add_option("--pdf", a->pdf, "Write the drawing as a one-page PDF (page = paper)");
            cmd.add_flag("--json", a->json, "Print the corner list as JSON");
            return [a]() {
              vision::TargetBoard board;
              try {
                board = vision::load_target_file(a->target);
                if (!a->svg.empty()) vision::save_target_svg(board, a->svg);
                if (!a->pdf.empty()) vision::save_target_pdf(board, a->pdf);
              } catch (const vision::FileFormatError& e) {
                throw InputError(e.what());
              }
              const Eigen::Vector2d size = board.extent_max - board.extent_min;
              const std::vector<std::string> warnings = print_warnings(board, size, *a);
              for (const std::string& w : warnings) fmt::print(stderr, "warning: {}\n", w);
              if (a->json) {
                nlohmann::json corners = nlohmann::json::array();
                for (const auto& c : board.corners)
                  corners.push_back({{"id", c.id}, {"x", c.point.x()}, {"y", c.point.y()}});
                write_json({{"type", vision::target_kind_name(board.spec.kind)},
                            {"paper_m", {size.x(), size.y()}},
                            {"warnings", warnings},
                            {"corners", corners}},
                           "-");
              } else {
                fmt::print("{} {}x{}: {} corners, {} markers, paper {:.1f} x {:.1f} mm\n",
                           vision::target_kind_name(board.spec.kind), board.spec.cols,
                           board.spec.rows, board.corners.size(), board.markers.size(),
                           size.x() * 1000, size.y() * 1000);
                if (!a->svg.empty())
                  fmt::print("wrote {} (print at 100 %, check the size with a ruler)\n", a->svg);
                if (!a->pdf.empty()) fmt::print("wrote {}\n", a->pdf);
              }
              return int{kExitOk};
            };
          }};
}

}  // namespace robocal::app
