// `robocal intrinsics`: calibrate a camera from a folder of images of a target.
#include <fmt/core.h>

#include <cmath>
#include <filesystem>
#include <memory>

#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/staging.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/errors.hpp"
#include "robocal/vision/intrinsics_pipeline.hpp"
#include "robocal/vision/target_io.hpp"

namespace robocal::app {
namespace {

struct IntrinsicsArgs {
  std::string images;
  std::string target;
  std::string model = "pinhole_radtan";
  std::string camera_out = "camera.yaml";
  std::string report_out = "intrinsics_report.json";
  std::string svg_out = "coverage.svg";
  float decimate = 2.0f;
  int threads = 1;
};

nlohmann::json finite_or_null(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
}

nlohmann::json report_json(const vision::IntrinsicsRun& run) {
  using vision::CalibrationStatus;
  const auto& c = run.calibration;
  nlohmann::json images = nlohmann::json::array();
  for (const auto& im : run.images) {
    nlohmann::json j = {{"file", im.file}};
    if (!im.error.empty()) {
      j["status"] = "error";
      j["error"] = im.error;
    } else {
      j["status"] = vision::detection_status_name(im.status);
      if (!im.detail.empty()) j["detail"] = im.detail;
      j["corners"] = im.corners;
      j["edge_blur_px"] = finite_or_null(im.edge_blur_px);
    }
    images.push_back(j);
  }
  nlohmann::json views = nlohmann::json::array();
  for (const auto& v : c.views) {
    nlohmann::json j = {{"name", v.name}, {"used", v.used}, {"corners", v.corners}};
    if (!v.rejection.empty()) j["rejection"] = v.rejection;
    if (v.used) {
      j["rms_px"] = v.rms_px;
      j["tilt_deg"] = v.tilt_deg;
      j["outliers"] = v.outliers;
      const Eigen::Vector3d t = v.camera_T_board.translation();
      j["camera_T_board_translation_m"] = {t.x(), t.y(), t.z()};
    }
    views.push_back(j);
  }
  nlohmann::json doc = {
      {"status", c.status == CalibrationStatus::kOk        ? "ok"
                 : c.status == CalibrationStatus::kRefused ? "refused"
                                                           : "failed"},
      {"image_size", {run.width, run.height}},
      {"images", images},
      {"views", views},
      {"warnings", c.warnings},
      {"advice", c.advice},
      {"uncovered_regions", c.uncovered_regions},
  };
  if (!c.reason.empty()) doc["reason"] = c.reason;
  if (c.status == CalibrationStatus::kOk) {
    nlohmann::json params = nlohmann::json::object();
    for (size_t i = 0; i < c.param_names.size(); ++i) {
      params[c.param_names[i]] = {{"value", c.camera.params[i]},
                                  {"sigma", finite_or_null(c.param_stddev[i])}};
    }
    doc["model"] = std::string(vision::kind_name(c.camera.kind));
    doc["parameters"] = params;
    doc["rms_px"] = c.rms_px;
    doc["residual_sigma_px"] = c.residual_sigma_px;
    doc["corners_used"] = c.corners_used;
    doc["corners_rejected"] = c.corners_rejected;
    doc["converged"] = c.converged;
    doc["iterations"] = c.iterations;
    nlohmann::json sigma_map = nlohmann::json::array();
    for (double v : c.coverage.projection_sigma_px) sigma_map.push_back(finite_or_null(v));
    doc["coverage"] = {{"cols", c.coverage.cols},
                       {"rows", c.coverage.rows},
                       {"corner_count", c.coverage.corner_count},
                       {"projection_sigma_px_at_1m", sigma_map}};
    nlohmann::json residuals = nlohmann::json::array();
    for (const auto& r : c.residuals) {
      residuals.push_back(
          {{"view", r.view},
           {"corner_id", r.corner_id},
           {"pixel", {r.pixel.x(), r.pixel.y()}},
           {"residual", {finite_or_null(r.residual.x()), finite_or_null(r.residual.y())}},
           {"outlier", r.outlier}});
    }
    doc["corner_residuals"] = residuals;
  }
  return doc;
}

}  // namespace

CommandSpec intrinsics_command() {
  return {
      "intrinsics", "Calibrate a camera's intrinsics from a folder of images of a target",
      [](CLI::App& cmd) -> CommandAction {
        auto a = std::make_shared<IntrinsicsArgs>();
        cmd.add_option("--images", a->images, "Folder with the images")->required();
        cmd.add_option("--target", a->target, "Target file (YAML)")->required();
        cmd.add_option("--model", a->model,
                       "Camera model: pinhole_radtan, pinhole_rational, fisheye_kb4")
            ->capture_default_str();
        cmd.add_option("-o,--camera", a->camera_out, "Camera file to write")->capture_default_str();
        cmd.add_option("--report", a->report_out, "JSON report to write ('-' = stdout)")
            ->capture_default_str();
        cmd.add_option("--svg", a->svg_out, "Coverage / uncertainty SVG to write")
            ->capture_default_str();
        cmd.add_option("--decimate", a->decimate, "AprilTag quad decimation")
            ->check(CLI::Range(1.0, 8.0))
            ->capture_default_str();
        cmd.add_option("--threads", a->threads, "AprilTag detector threads")
            ->check(CLI::Range(1, 64))
            ->capture_default_str();
        return [a]() {
          const auto kind = vision::kind_from_name(a->model);
          if (!kind)
            throw UsageError("--model: unknown camera model '" + a->model +
                             "' (pinhole_radtan, pinhole_rational or fisheye_kb4)");
          vision::TargetBoard board;
          try {
            board = vision::load_target_file(a->target);
          } catch (const vision::FileFormatError& e) {
            throw InputError(e.what());
          }
          vision::IntrinsicsPipelineOptions opt;
          opt.calibration.kind = *kind;
          opt.apriltag.quad_decimate = a->decimate;
          opt.apriltag.threads = a->threads;
          vision::IntrinsicsRun run;
          try {
            run = vision::calibrate_from_folder(a->images, board, opt);
          } catch (const std::invalid_argument& e) {
            throw InputError(e.what());
          }
          for (const auto& im : run.images) {
            if (!im.error.empty()) {
              fmt::print(stderr, "skipped {}\n", im.error);
            } else {
              fmt::print("{:<28} {:<9} {:>4} corners{}{}\n", im.file,
                         vision::detection_status_name(im.status), im.corners,
                         im.detail.empty() ? "" : "  ", im.detail);
            }
          }
          const auto& c = run.calibration;
          // The report, camera file and SVG are replaced together or not at all
          // (core/staging.hpp); a refused calibration writes its report alone (why, and which
          // views to add), never a camera file.
          core::StagedFiles files;
          const bool report_to_stdout = a->report_out.empty() || a->report_out == "-";
          if (report_to_stdout)
            write_json(report_json(run), "-");
          else
            files.add(a->report_out, report_json(run).dump(2) + "\n");
          for (const auto& w : c.warnings) fmt::print("warning: {}\n", w);
          for (const auto& adv : c.advice) fmt::print("advice: {}\n", adv);
          if (c.status != vision::CalibrationStatus::kOk) {
            files.commit();
            fmt::print(stderr, "calibration {}: {}\n",
                       c.status == vision::CalibrationStatus::kRefused ? "refused" : "failed",
                       c.reason);
            return int{kExitFailure};
          }
          files.add(a->camera_out, vision::camera_to_yaml(c.camera));
          if (!a->svg_out.empty())
            files.add(a->svg_out, vision::coverage_svg(c, run.width, run.height));
          files.commit();
          for (size_t i = 0; i < c.param_names.size(); ++i) {
            fmt::print("{:<3} = {:>14.6f} +- {:.6f}\n", c.param_names[i], c.camera.params[i],
                       c.param_stddev[i]);
          }
          fmt::print(
              "RMS {:.4f} px over {} corners ({} rejected), {} views used\n", c.rms_px,
              c.corners_used, c.corners_rejected,
              std::count_if(c.views.begin(), c.views.end(), [](const auto& v) { return v.used; }));
          return int{kExitOk};
        };
      }};
}

}  // namespace robocal::app
