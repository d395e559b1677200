#pragma once
// Files around the renderer: the views to render (YAML/JSON) and the ground truth written
// beside each image (JSON).
//
// Views file (YAML; JSON is accepted too):
//   views:
//     - name: view000                 # optional; default viewNNN; image <name>.png
//       poses:                        # camera_T_board of each target, in target order
//         - {rvec: [0.1, -0.2, 0.0], t: [-0.1, -0.05, 0.6]}   # rvec: axis*angle (rad), t: m
//       occluders:                    # optional, image coordinates (pixels)
//         - {disc: [cx, cy, radius], level: 10}
//         - {rectangle: [cx, cy, half_width, half_height], level: 240}
//       seed: 7                       # optional noise seed of this view (default: index + 1)
//
// Truth file (JSON): {"format": "robocal-render-truth-1", "pixel_convention": "opencv_center",
//   "image": "view000.png", "camera": {model, width, height, params}, "targets": [{"name",
//   "type", "camera_T_board": {"rvec", "t", "matrix"}}], "options": {...}, "corners":
//   [{"target", "id", "x", "y", "visible", "occluded"}]}  (x, y null when not projectable)
#include "robocal/vision/errors.hpp"
#include "robocal/vision/renderer.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace robocal::vision {

struct RenderView {
  std::string name;
  std::vector<Eigen::Isometry3d> camera_T_board;  // one per target
  std::vector<Occluder> occluders;
  std::uint64_t seed = 1;
};

// Throws FileFormatError("<file>:<line>: ...") on errors, including a pose count that differs
// from `num_targets`.
std::vector<RenderView> load_render_views(const std::filesystem::path& path, int num_targets);
std::vector<RenderView> parse_render_views(const std::string& text, const std::string& source,
                                           int num_targets);

struct RenderTruth {
  std::string image;
  CameraModel camera;
  std::vector<std::string> target_names;
  std::vector<Eigen::Isometry3d> camera_T_board;
  std::vector<CornerTruth> corners;
};

std::string render_truth_json(const std::string& image_name, const CameraModel& camera,
                              const std::vector<RenderTarget>& targets,
                              const RenderOptions& options,
                              const std::vector<CornerTruth>& corners);
// Reads a truth file written by render_truth_json. Throws FileFormatError.
RenderTruth load_render_truth(const std::filesystem::path& path);

}  // namespace robocal::vision
