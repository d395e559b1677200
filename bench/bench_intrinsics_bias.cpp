// Where the signed error of the demo's intrinsic calibration comes from, printed as JSON.
//
// Rebuilds exactly the cameras and the intrinsic calibration views `robocal simulate --seed N`
// makes (same random stream: the images of the `demo` condition are the session's own), then
// calibrates each camera under conditions that separate the candidate causes:
//   corners:  detected (the pipeline: detector corners with their covariances) | unweighted (the
//             same corners, equal weights) | truth (the renderer's projections, exact) |
//             truth_iid (truth + independent Gaussian noise of the detected per-axis RMS, several
//             draws) | truth_plus_radial (truth + the detected error's mean radial part per
//             image-radius bin: is the bias the corners' radial error?)
//   images:   demo | no_noise | no_distortion (truth camera without distortion, same poses) |
//             no_blur (noise off too: the deterministic detector + renderer error alone)
// Per camera and condition: parameter errors against the truth and error / predicted sigma (z),
// and the detected corners' error against the truth: RMS, mean, and the mean radial error (from
// the true principal point) per image-radius bin.
//
//   bench_intrinsics_bias [--seeds 1,2,3] [--views 48] [--images demo,no_distortion,...]
//                         [--iid-trials 4] [--cameras 0,1] [--threads 2]
// Image conditions are tokens joined by '+' (demo, no_noise, no_blur, no_distortion,
// no_lighting, blur=SIGMA, sub=N), optionally with "@K" for another noise draw.
// Also printed: fx_attribution, the linearised share of the fx error per view, image radius,
// board ring and per tag deformation mode (translation, scale, rotation, affine, projective),
// and tag_expansion: per-tag size, aspect and taper (keystone) errors.
//
// Finding (seeds 1-3, both cameras, 48 views): the focal error came from the edge fit
// modelling the tag border with constant grey levels while vignetting and the lighting gradient
// ramp them along each edge. The ramp rotated each fitted edge, which exaggerated every tag's
// perspective taper by ~0.6 % (+0.022 px on tags tapered >= 3 px) - more perspective reads as a
// shorter focal length, and the distortion terms followed along the valley (k1 +, k2 -, k3 +).
// With no_lighting the taper error and the projective share vanish; distortion, blur sub-cells,
// noise, weighting and the solver's start (detected_from_truth: same minimum) do not matter.
// Before / after the edge fit modelled a gain ramp along the edge (detected, 12 calibrations):
// fx error -0.033 +- 0.007 px (z -1.23, k1 +1.6, k3 +2.5) -> -0.009 +- 0.005 (z -0.65,
// k1 -0.4, k3 -0.7); noise-free -0.013 -> -0.006 +- 0.001 px (the rest: unrefined library
// corners of tags cut by the image border; refined tags alone -0.0003 +- 0.002); corner error
// RMS 0.018 -> 0.013 px, sigma(fx) 0.026 -> 0.014 px.
#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/camera_parameter_names.hpp"
#include "robocal/vision/intrinsic_calibration.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/target_detection.hpp"
#include "session/session_robot.hpp"
#include "simcell/simulated_cell.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <iostream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace rv = robocal::vision;
namespace ra = robocal::app;
using Eigen::Vector2d;
using json = nlohmann::json;

namespace {

struct Scene {
  rv::CameraModel camera;  // truth
  rv::TargetBoard board;
  std::vector<Eigen::Isometry3d> poses;  // camera_T_board
  std::vector<std::uint64_t> seeds;      // render seeds, as simulate draws them
  rv::RenderOptions render;
};

// The two cameras' scenes of `robocal simulate --seed seed` (same random stream as
// simulate_session: cell, then per camera its views and one render seed per view).
std::vector<Scene> demo_scenes(unsigned seed, int views) {
  std::mt19937 rng(seed);
  ra::CellOptions options;
  const ra::SimulatedCell cell =
      ra::make_simulated_cell(ra::resolve_robot("rotary_delta"), options, rng);
  std::vector<Scene> scenes;
  for (int c = 0; c < static_cast<int>(cell.cameras.size()); ++c) {
    Scene s;
    s.camera = cell.cameras[static_cast<std::size_t>(c)].model;
    s.board = cell.calibration_board;
    s.render = cell.options.render;
    s.poses = ra::intrinsic_view_poses(cell, c, views, rng);
    for (std::size_t v = 0; v < s.poses.size(); ++v) s.seeds.push_back(rng());
    scenes.push_back(std::move(s));
  }
  return scenes;
}

struct ViewData {
  rv::TargetDetection detection;
  std::vector<Vector2d> truth;  // per detected corner
};

// `images` is a condition name, optionally with "@K": noise seeds offset by K (another noise
// draw on the same views).
std::vector<ViewData> render_and_detect(const Scene& scene, const std::string& condition,
                                        int threads) {
  const auto at = condition.find('@');
  const std::string images = condition.substr(0, at);
  const std::uint64_t offset = at == std::string::npos ? 0 : std::stoull(condition.substr(at + 1));
  rv::CameraModel camera = scene.camera;
  rv::RenderOptions render = scene.render;
  // Tokens joined by '+': demo, no_distortion, no_noise, no_blur (noise off too), no_lighting,
  // blur=SIGMA, sub=N (renderer sub-cells per edge pixel).
  std::stringstream tokens(images);
  std::string token;
  while (std::getline(tokens, token, '+')) {
    if (token == "no_distortion")
      for (std::size_t i = 4; i < camera.params.size(); ++i) camera.params[i] = 0.0;
    if (token == "no_noise" || token == "no_blur") render.read_noise = 0.0;
    if (token == "no_blur") render.blur_sigma = 0.0;
    if (token == "no_lighting") {
      render.vignetting = 0.0;
      render.lighting_gradient.setZero();
    }
    if (token.starts_with("blur=")) render.blur_sigma = std::stod(token.substr(5));
    if (token.starts_with("sub=")) render.blur_subcells = std::stoi(token.substr(4));
  }
  const rv::CameraRays rays = rv::precompute_rays(camera);
  std::vector<ViewData> out(scene.poses.size());
  std::vector<std::thread> workers;
  for (int t = 0; t < threads; ++t) {
    workers.emplace_back([&, t] {
      rv::AprilTagDetector detector;
      for (std::size_t v = static_cast<std::size_t>(t); v < scene.poses.size();
           v += static_cast<std::size_t>(threads)) {
        rv::RenderOptions o = render;
        o.seed = scene.seeds[v] + offset * 7919;
        const auto r = rv::render(rays, {{scene.board, scene.poses[v]}}, o);
        ViewData& d = out[v];
        d.detection = rv::detect_target(r.image, scene.board, detector);
        for (int id : d.detection.corner_ids) {
          Vector2d px(NAN, NAN);
          for (const auto& c : r.corners)
            if (c.id == id) px = c.pixel;
          d.truth.push_back(px);
        }
      }
    });
  }
  for (auto& w : workers) w.join();
  return out;
}

// Radius bins (px from the true principal point) of the corner-error analysis.
constexpr double kBinPx = 200.0;
constexpr int kBins = 6;

int bin_of(double r) {
  return std::min(kBins - 1, static_cast<int>(r / kBinPx));
}

struct CornerErrors {
  int corners = 0;
  double rms = 0, mean_u = 0, mean_v = 0, per_axis_rms = 0;
  std::array<double, kBins> radial_mean{}, tangential_mean{}, radial_rms{};
  std::array<int, kBins> count{};
  json to_json() const {
    json bins = json::array();
    for (int b = 0; b < kBins; ++b)
      bins.push_back({{"r_px", {b * kBinPx, (b + 1) * kBinPx}},
                      {"corners", count[static_cast<std::size_t>(b)]},
                      {"radial_mean_px", radial_mean[static_cast<std::size_t>(b)]},
                      {"tangential_mean_px", tangential_mean[static_cast<std::size_t>(b)]},
                      {"radial_rms_px", radial_rms[static_cast<std::size_t>(b)]}});
    return {{"corners", corners},
            {"rms_px", rms},
            {"per_axis_rms_px", per_axis_rms},
            {"mean_px", {mean_u, mean_v}},
            {"by_radius", bins}};
  }
};

// Over the corners of refined tags (refined = true) or of the tags the edge fit left alone.
CornerErrors corner_errors(const std::vector<ViewData>& views, const rv::CameraModel& camera,
                           bool refined_tags) {
  CornerErrors e;
  const Vector2d c(camera.params[2], camera.params[3]);
  double sq = 0;
  int n = 0;
  for (const auto& v : views) {
    std::set<int> refined;
    for (const auto& g : v.detection.corner_groups)
      refined.insert(g.corner_ids.begin(), g.corner_ids.end());
    for (std::size_t i = 0; i < v.truth.size(); ++i) {
      if (!v.truth[i].allFinite()) continue;
      if ((refined.count(v.detection.corner_ids[i]) != 0) != refined_tags) continue;
      const Vector2d err = v.detection.pixels[i] - v.truth[i];
      if (std::getenv("DUMP") && err.norm() > 0.1)
        std::cerr << "big error " << err.transpose() << " at " << v.truth[i].transpose() << " id "
                  << v.detection.corner_ids[i] << "\n";
      const Vector2d d = v.truth[i] - c;
      const double r = d.norm();
      const Vector2d radial = r > 0 ? Vector2d(d / r) : Vector2d(1, 0);
      const auto b = static_cast<std::size_t>(bin_of(r));
      e.radial_mean[b] += err.dot(radial);
      e.tangential_mean[b] += err.x() * -radial.y() + err.y() * radial.x();
      e.radial_rms[b] += err.dot(radial) * err.dot(radial);
      ++e.count[b];
      e.mean_u += err.x();
      e.mean_v += err.y();
      sq += err.squaredNorm();
      ++n;
    }
  }
  e.corners = n;
  for (int b = 0; b < kBins; ++b) {
    const auto k = static_cast<std::size_t>(b);
    if (e.count[k] == 0) continue;
    e.radial_mean[k] /= e.count[k];
    e.tangential_mean[k] /= e.count[k];
    e.radial_rms[k] = std::sqrt(e.radial_rms[k] / e.count[k]);
  }
  e.mean_u /= std::max(1, n);
  e.mean_v /= std::max(1, n);
  e.rms = std::sqrt(sq / std::max(1, n));
  e.per_axis_rms = std::sqrt(sq / std::max(1, 2 * n));
  return e;
}

// Per refined tag: the mean outward error of its corners (from the tag's true centre), px: how
// much bigger than the truth the detector sees the tag. A constant pixel expansion is relatively
// larger on small (far, foreshortened) tags: it mimics weaker perspective.
struct TagExpansion {
  std::map<std::pair<std::size_t, int>, double> by_tag;  // (view, tag) -> px
  double mean = 0, rms = 0;
  int tags = 0;
  std::array<double, 4> mean_by_size{};  // tag side (px): <60, 60-90, 90-120, >=120
  std::array<int, 4> count_by_size{};
  // Mean error of the tag's short and long side lengths (px) by foreshortening (short / long
  // side: < 0.7, 0.7-0.85, >= 0.85): is a tilted tag seen too square or too narrow?
  std::array<double, 3> short_error{}, long_error{};
  std::array<int, 3> count_by_ratio{};
  // Mean error of the taper (length difference of opposite sides; > 0: exaggerated) by the
  // true taper: < 1 px, 1-3 px, >= 3 px.
  std::array<double, 3> keystone_error{};
  std::array<int, 3> count_by_taper{};
  json to_json() const {
    return {{"tags", tags},
            {"mean_px", mean},
            {"rms_px", rms},
            {"mean_px_by_side",
             {{"lt60", mean_by_size[0]},
              {"60_90", mean_by_size[1]},
              {"90_120", mean_by_size[2]},
              {"ge120", mean_by_size[3]}}},
            {"tags_by_side", count_by_size},
            {"short_side_error_px_by_ratio", short_error},
            {"long_side_error_px_by_ratio", long_error},
            {"tags_by_ratio", count_by_ratio},
            {"taper_error_px_by_taper", keystone_error},
            {"sides_by_taper", count_by_taper}};
  }
};

TagExpansion tag_expansion(const std::vector<ViewData>& views) {
  TagExpansion t;
  double sum = 0, sq = 0;
  for (std::size_t v = 0; v < views.size(); ++v) {
    const auto& d = views[v].detection;
    for (const auto& g : d.corner_groups) {
      std::array<Vector2d, 4> truth, det;
      bool ok = g.corner_ids.size() == 4;
      for (std::size_t k = 0; k < 4 && ok; ++k) {
        const auto it = std::find(d.corner_ids.begin(), d.corner_ids.end(), g.corner_ids[k]);
        ok = it != d.corner_ids.end();
        if (!ok) break;
        const auto i = static_cast<std::size_t>(it - d.corner_ids.begin());
        truth[k] = views[v].truth[i];
        det[k] = d.pixels[i];
        ok = truth[k].allFinite();
      }
      if (!ok) continue;
      const Vector2d c = 0.25 * (truth[0] + truth[1] + truth[2] + truth[3]);
      double e = 0, side = 0;
      for (std::size_t k = 0; k < 4; ++k) {
        e += 0.25 * (det[k] - truth[k]).dot((truth[k] - c).normalized());
        side += 0.25 * (truth[(k + 1) % 4] - truth[k]).norm();
      }
      t.by_tag[{v, g.corner_ids[0] / 4}] = e;
      // Side lengths along the tag's two axes (mean of the opposite sides), short and long.
      auto len = [](const std::array<Vector2d, 4>& q, int axis) {
        return axis == 0 ? 0.5 * ((q[1] - q[0]).norm() + (q[2] - q[3]).norm())
                         : 0.5 * ((q[3] - q[0]).norm() + (q[2] - q[1]).norm());
      };
      const int short_axis = len(truth, 0) < len(truth, 1) ? 0 : 1;
      const double ratio = len(truth, short_axis) / len(truth, 1 - short_axis);
      const auto rb = static_cast<std::size_t>(ratio < 0.7 ? 0 : ratio < 0.85 ? 1 : 2);
      // Keystone: the length difference of opposite sides (the tag's perspective taper),
      // detected minus true, signed so that > 0 exaggerates the true taper.
      for (std::size_t pair = 0; pair < 2; ++pair) {
        const auto side_len = [&](const std::array<Vector2d, 4>& q, std::size_t k) {
          return (q[(k + 1) % 4] - q[k]).norm();
        };
        const double taper_true = side_len(truth, pair) - side_len(truth, pair + 2);
        const double taper_det = side_len(det, pair) - side_len(det, pair + 2);
        const double sign = taper_true >= 0 ? 1.0 : -1.0;
        const auto kb = static_cast<std::size_t>(std::abs(taper_true) < 1.0   ? 0
                                                 : std::abs(taper_true) < 3.0 ? 1
                                                                              : 2);
        t.keystone_error[kb] += sign * (taper_det - taper_true);
        ++t.count_by_taper[kb];
      }
      t.short_error[rb] += len(det, short_axis) - len(truth, short_axis);
      t.long_error[rb] += len(det, 1 - short_axis) - len(truth, 1 - short_axis);
      ++t.count_by_ratio[rb];
      sum += e;
      sq += e * e;
      ++t.tags;
      const auto b = static_cast<std::size_t>(side < 60 ? 0 : side < 90 ? 1 : side < 120 ? 2 : 3);
      t.mean_by_size[b] += e;
      ++t.count_by_size[b];
    }
  }
  t.mean = sum / std::max(1, t.tags);
  t.rms = std::sqrt(sq / std::max(1, t.tags));
  for (std::size_t b = 0; b < 4; ++b)
    if (t.count_by_size[b] > 0) t.mean_by_size[b] /= t.count_by_size[b];
  for (std::size_t b = 0; b < 3; ++b)
    if (t.count_by_taper[b] > 0) t.keystone_error[b] /= t.count_by_taper[b];
  for (std::size_t b = 0; b < 3; ++b)
    if (t.count_by_ratio[b] > 0) {
      t.short_error[b] /= t.count_by_ratio[b];
      t.long_error[b] /= t.count_by_ratio[b];
    }
  return t;
}

json calibrate(const std::vector<rv::CalibrationView>& views, const rv::CameraModel& truth,
               const rv::CameraModel& reference, bool start_at_truth = false) {
  rv::IntrinsicCalibrationOptions o;
  o.width = truth.width;
  o.height = truth.height;
  if (start_at_truth) o.initial_params = truth.params;
  const auto r = rv::calibrate_intrinsics(views, o);
  if (r.status != rv::CalibrationStatus::kOk) return {{"status", "failed"}, {"reason", r.reason}};
  json err, z;
  const auto names = rv::camera_param_names(truth.kind);
  for (std::size_t i = 0; i < names.size(); ++i) {
    err[names[i]] = r.camera.params[i] - reference.params[i];
    z[names[i]] = (r.camera.params[i] - reference.params[i]) / r.param_stddev[i];
  }
  return {{"status", "ok"},
          {"rms_px", r.rms_px},
          {"error", err},
          {"z", z},
          {"sigma_fx", r.param_stddev[0]},
          {"outliers", r.corners_rejected}};
}

std::vector<rv::CalibrationView> views_of(const std::vector<ViewData>& data,
                                          const std::string& corners, std::mt19937* rng,
                                          double iid_sigma, const CornerErrors& radial_model,
                                          const TagExpansion& expansion,
                                          const rv::CameraModel& camera) {
  std::vector<rv::CalibrationView> views;
  std::normal_distribution<double> noise(0.0, iid_sigma);
  const Vector2d c(camera.params[2], camera.params[3]);
  for (std::size_t v = 0; v < data.size(); ++v) {
    if (data[v].detection.status == rv::DetectionStatus::kRejected) continue;
    rv::CalibrationView view = rv::to_calibration_view(data[v].detection, std::to_string(v));
    if (corners.ends_with("_refined")) {
      // Only the corners of tags the edge fit refined (they carry a covariance group).
      std::set<int> refined;
      for (const auto& g : view.corner_groups)
        refined.insert(g.corner_ids.begin(), g.corner_ids.end());
      rv::CalibrationView kept;
      kept.name = view.name;
      kept.corner_groups = view.corner_groups;
      for (std::size_t i = 0; i < view.pixels.size(); ++i) {
        if (refined.count(view.corner_ids[i]) == 0) continue;
        kept.corner_ids.push_back(view.corner_ids[i]);
        kept.board_points.push_back(view.board_points[i]);
        kept.pixels.push_back(view.pixels[i]);
      }
      view = std::move(kept);
    }
    if (corners == "unweighted_refined") view.corner_groups.clear();
    if (!corners.starts_with("detected")) view.corner_groups.clear();
    if (corners.starts_with("truth")) {
      for (std::size_t i = 0; i < view.pixels.size(); ++i) {
        view.pixels[i] = data[v].truth[i];
        if (corners == "truth_plus_tag_expansion" || corners == "truth_plus_mean_expansion") {
          // Along the corner's outward direction from its tag's true centre.
          const int tag = view.corner_ids[i] / 4;
          const auto it = expansion.by_tag.find({v, tag});
          if (it == expansion.by_tag.end()) continue;
          Vector2d centre = Vector2d::Zero();
          int n = 0;
          for (std::size_t k = 0; k < view.pixels.size(); ++k)
            if (view.corner_ids[k] / 4 == tag) {
              centre += data[v].truth[k];
              ++n;
            }
          centre /= n;
          const double e = corners == "truth_plus_tag_expansion" ? it->second : expansion.mean;
          view.pixels[i] += e * (data[v].truth[i] - centre).normalized();
        }
        if (corners == "truth_iid") view.pixels[i] += Vector2d(noise(*rng), noise(*rng));
        if (corners == "truth_plus_radial") {
          const Vector2d d = data[v].truth[i] - c;
          const double r = d.norm();
          if (r > 0)
            view.pixels[i] += radial_model.radial_mean[static_cast<std::size_t>(bin_of(r))] * d / r;
        }
      }
    }
    views.push_back(std::move(view));
  }
  return views;
}

// Linearised attribution of the focal-length error to the corners: at the truth (true camera,
// true board poses), the unweighted least-squares step is (J^T J)^-1 J^T e with e the detected
// minus true corners (refined tags only, as unweighted_refined). Row fx of that operator times
// each corner's error is the corner's share of the fx error; the shares are summed by view, by
// image radius and by where the corner sits on the board.
json fx_attribution(const std::vector<ViewData>& data, const Scene& scene,
                    const rv::CameraModel& truth) {
  struct Row {
    std::size_t view;
    Eigen::Vector3d board;
    Vector2d error;
    Vector2d pixel;
    int corner_id;
  };
  std::vector<Row> rows;
  std::vector<std::size_t> view_index(data.size(), SIZE_MAX);
  std::size_t n_views = 0;
  for (std::size_t v = 0; v < data.size(); ++v) {
    const auto& d = data[v].detection;
    if (d.status == rv::DetectionStatus::kRejected) continue;
    std::set<int> refined;
    for (const auto& g : d.corner_groups) refined.insert(g.corner_ids.begin(), g.corner_ids.end());
    for (std::size_t i = 0; i < d.pixels.size(); ++i) {
      if (refined.count(d.corner_ids[i]) == 0 || !data[v].truth[i].allFinite()) continue;
      const Vector2d e = d.pixels[i] - data[v].truth[i];
      if (e.norm() > 0.1) continue;  // the calibration's outliers
      if (view_index[v] == SIZE_MAX) view_index[v] = n_views++;
      rows.push_back({v, d.board_points[i], e, data[v].truth[i], d.corner_ids[i]});
    }
  }
  const int np = static_cast<int>(truth.params.size());
  const Eigen::Index cols = np + 6 * static_cast<Eigen::Index>(n_views);
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(2 * static_cast<Eigen::Index>(rows.size()), cols);
  Eigen::VectorXd e(2 * static_cast<Eigen::Index>(rows.size()));
  for (std::size_t r = 0; r < rows.size(); ++r) {
    const Eigen::Isometry3d& pose = scene.poses[rows[r].view];
    const Eigen::Vector3d rx = pose.linear() * rows[r].board;
    Vector2d px;
    Eigen::Matrix<double, 2, 3> dp;
    Eigen::MatrixXd dk;
    rv::project_jacobians(truth, rx + pose.translation(), &px, &dp, &dk);
    const auto row = static_cast<Eigen::Index>(2 * r);
    j.block(row, 0, 2, np) = dk;
    Eigen::Matrix3d skew;
    skew << 0, -rx.z(), rx.y(), rx.z(), 0, -rx.x(), -rx.y(), rx.x(), 0;
    const Eigen::Index c0 = np + 6 * static_cast<Eigen::Index>(view_index[rows[r].view]);
    j.block(row, c0, 2, 3) = -dp * skew;  // d(omega x RX) / d omega = -[RX]x
    j.block(row, c0 + 3, 2, 3) = dp;
    e.segment<2>(row) = rows[r].error;
  }
  const Eigen::MatrixXd jtj = j.transpose() * j;
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(jtj);
  Eigen::VectorXd unit = Eigen::VectorXd::Zero(cols);
  unit(0) = 1.0;
  const Eigen::VectorXd g = j * ldlt.solve(unit);  // influence of each residual on fx
  std::vector<double> by_view(data.size(), 0.0);
  std::array<double, kBins> by_radius{};
  double border_tags = 0, inner_tags = 0, radial = 0, tangential = 0;
  const Vector2d c(truth.params[2], truth.params[3]);
  const int cols_board = scene.board.spec.cols, rows_board = scene.board.spec.rows;
  for (std::size_t r = 0; r < rows.size(); ++r) {
    const auto row = static_cast<Eigen::Index>(2 * r);
    const Vector2d gi = g.segment<2>(row);
    const double share = gi.dot(rows[r].error);
    by_view[rows[r].view] += share;
    const Vector2d d = rows[r].pixel - c;
    by_radius[static_cast<std::size_t>(bin_of(d.norm()))] += share;
    const Vector2d rad = d.normalized();
    radial += gi.dot(rad) * rows[r].error.dot(rad);
    tangential += share - gi.dot(rad) * rows[r].error.dot(rad);
    const int tag = rows[r].corner_id / 4 - scene.board.spec.first_id;
    const int tc = tag % cols_board, tr = tag / cols_board;
    const bool border = tc == 0 || tr == 0 || tc == cols_board - 1 || tr == rows_board - 1;
    (border ? border_tags : inner_tags) += share;
  }
  // Per tag: its four corner errors split into orthonormal modes of the tag's true corners
  // (translation x, y; scale; rotation; the other two affine modes; the two projective ones),
  // each mode's share of the fx error summed over all tags.
  const std::array<const char*, 8> mode_names = {"translation_x", "translation_y", "scale",
                                                 "rotation",      "affine_a",      "affine_b",
                                                 "projective_a",  "projective_b"};
  std::array<double, 8> mode_share{};
  std::map<std::pair<std::size_t, int>, std::array<std::size_t, 4>> tags;
  std::map<std::pair<std::size_t, int>, int> tag_count;
  for (std::size_t r = 0; r < rows.size(); ++r) {
    const std::pair<std::size_t, int> key{rows[r].view, rows[r].corner_id / 4};
    tags[key][static_cast<std::size_t>(rows[r].corner_id % 4)] = r;
    ++tag_count[key];
  }
  for (const auto& [key, idx] : tags) {
    if (tag_count[key] != 4) continue;
    Vector2d centre = Vector2d::Zero();
    for (std::size_t k : idx) centre += 0.25 * rows[k].pixel;
    Eigen::Matrix<double, 8, 8> basis = Eigen::Matrix<double, 8, 8>::Zero();
    for (std::size_t k = 0; k < 4; ++k) {
      const Vector2d d = rows[idx[k]].pixel - centre;
      const auto row = static_cast<Eigen::Index>(2 * k);
      basis.block<2, 1>(row, 0) = Vector2d(1, 0);
      basis.block<2, 1>(row, 1) = Vector2d(0, 1);
      basis.block<2, 1>(row, 2) = d;
      basis.block<2, 1>(row, 3) = Vector2d(-d.y(), d.x());
      basis.block<2, 1>(row, 4) = Vector2d(d.x(), -d.y());
      basis.block<2, 1>(row, 5) = Vector2d(d.y(), d.x());
      // Projective: displacement quadratic in the corner offset.
      basis.block<2, 1>(row, 6) = d.x() * d;
      basis.block<2, 1>(row, 7) = d.y() * d;
    }
    const Eigen::HouseholderQR<Eigen::Matrix<double, 8, 8>> qr(basis);
    const Eigen::Matrix<double, 8, 8> q = qr.householderQ();
    Eigen::Matrix<double, 8, 1> ek, gk;
    for (std::size_t k = 0; k < 4; ++k) {
      ek.segment<2>(static_cast<Eigen::Index>(2 * k)) = rows[idx[k]].error;
      gk.segment<2>(static_cast<Eigen::Index>(2 * k)) =
          g.segment<2>(static_cast<Eigen::Index>(2 * idx[k]));
    }
    for (int m = 0; m < 8; ++m)
      mode_share[static_cast<std::size_t>(m)] += gk.dot(q.col(m)) * q.col(m).dot(ek);
  }
  json modes;
  for (std::size_t m = 0; m < 8; ++m) modes[mode_names[m]] = mode_share[m];
  json views = json::array();
  for (std::size_t v = 0; v < data.size(); ++v) {
    // Tilt of the board against the line of sight to its centre.
    const Eigen::Isometry3d& pose = scene.poses[v];
    const Vector2d mid = 0.5 * (scene.board.extent_min + scene.board.extent_max);
    const Eigen::Vector3d centre = pose * Eigen::Vector3d(mid.x(), mid.y(), 0.0);
    const double tilt = std::acos(std::abs(pose.linear().col(2).dot(centre.normalized()))) * 180.0 /
                        3.14159265358979323846;
    views.push_back({{"view", v},
                     {"fx_share_px", by_view[v]},
                     {"tilt_deg", tilt},
                     {"distance_m", centre.norm()}});
  }
  return {{"fx_error_linear_px", g.dot(e)},
          {"sigma_fx_iid_unit_px", std::sqrt(ldlt.solve(unit)(0))},
          {"by_radius", by_radius},
          {"radial_part_px", radial},
          {"tangential_part_px", tangential},
          {"border_tags_px", border_tags},
          {"inner_tags_px", inner_tags},
          {"tag_modes_px", modes},
          {"by_view", views}};
}

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(item);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> seeds = {"1", "2", "3"};
  std::vector<std::string> images = {"demo"};
  std::vector<std::string> cameras = {"0", "1"};
  int views = 48, iid_trials = 4, threads = 2;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--seeds")
      seeds = split(v);
    else if (k == "--images")
      images = split(v);
    else if (k == "--cameras")
      cameras = split(v);
    else if (k == "--views")
      views = std::stoi(v);
    else if (k == "--iid-trials")
      iid_trials = std::stoi(v);
    else if (k == "--threads")
      threads = std::max(1, std::stoi(v));
    else {
      std::cerr << "unknown option " << k << "\n";
      return 2;
    }
  }
  json runs = json::array();
  for (const auto& seed : seeds) {
    const auto scenes = demo_scenes(static_cast<unsigned>(std::stoul(seed)), views);
    for (const auto& cam : cameras) {
      const Scene& scene = scenes.at(std::stoul(cam));
      std::vector<ViewData> noise_free;  // the no_noise detections, when rendered (first)
      for (const auto& img : images) {
        rv::CameraModel truth = scene.camera;
        if (img.find("no_distortion") != std::string::npos)
          for (std::size_t i = 4; i < truth.params.size(); ++i) truth.params[i] = 0.0;
        const auto t0 = std::chrono::steady_clock::now();
        const auto data = render_and_detect(scene, img, threads);
        std::cerr << "  render+detect "
                  << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()
                  << " s\n";
        if (img == "no_noise") noise_free = data;
        const CornerErrors errors = corner_errors(data, truth, true);
        const TagExpansion expansion = tag_expansion(data);
        json run{{"seed", std::stoi(seed)},
                 {"camera", std::stoi(cam)},
                 {"images", img},
                 {"views", data.size()},
                 {"truth_params", truth.params},
                 {"corner_errors", errors.to_json()},
                 {"unrefined_corner_errors", corner_errors(data, truth, false).to_json()},
                 {"tag_expansion", expansion.to_json()}};
        std::mt19937 rng(4242 + static_cast<unsigned>(std::stoul(seed)));
        for (const std::string corners :
             {"detected", "unweighted", "detected_refined", "unweighted_refined", "truth",
              "truth_plus_radial", "truth_plus_tag_expansion", "truth_plus_mean_expansion"})
          run[corners] =
              calibrate(views_of(data, corners, &rng, 0.0, errors, expansion, truth), truth, truth);
        // The same corners, the solver started at the truth: a different minimum would be
        // the optimiser stopping early on the way from its zero-distortion start.
        run["detected_from_truth"] = calibrate(
            views_of(data, "detected", &rng, 0.0, errors, expansion, truth), truth, truth, true);
        run["fx_attribution"] = fx_attribution(data, scene, truth);
        if (!noise_free.empty() && img.starts_with("demo")) {
          // Split the detected error of each refined corner into its deterministic part (the
          // noise-free detection's error) and the noise's part (the rest), each calibrated on
          // its own with the noisy detection's corner covariances (weighted) or without.
          for (const std::string part : {"deterministic", "noise"}) {
            std::vector<ViewData> mixed = data;
            for (std::size_t v = 0; v < mixed.size(); ++v) {
              auto& d = mixed[v].detection;
              const auto& nf = noise_free[v].detection;
              for (std::size_t i = 0; i < d.pixels.size(); ++i) {
                const auto it =
                    std::find(nf.corner_ids.begin(), nf.corner_ids.end(), d.corner_ids[i]);
                if (it == nf.corner_ids.end()) {
                  d.pixels[i] = Vector2d(1e6, 1e6);  // an outlier: dropped
                  continue;
                }
                const Vector2d e_nf =
                    nf.pixels[static_cast<std::size_t>(it - nf.corner_ids.begin())] -
                    mixed[v].truth[i];
                const Vector2d e = d.pixels[i] - mixed[v].truth[i];
                d.pixels[i] = mixed[v].truth[i] + (part == "noise" ? Vector2d(e - e_nf) : e_nf);
              }
            }
            run[part + "_part_weighted"] =
                calibrate(views_of(mixed, "detected_refined", &rng, 0.0, errors, expansion, truth),
                          truth, truth);
            run[part + "_part_unweighted"] = calibrate(
                views_of(mixed, "unweighted_refined", &rng, 0.0, errors, expansion, truth), truth,
                truth);
          }
        }
        json iid = json::array();
        for (int t = 0; t < iid_trials; ++t)
          iid.push_back(calibrate(
              views_of(data, "truth_iid", &rng, errors.per_axis_rms, errors, expansion, truth),
              truth, truth));
        run["truth_iid"] = iid;
        std::cerr << "seed " << seed << " cam " << cam << " " << img << ": detected z(fx) "
                  << run["detected"]["z"]["fx"] << ", truth_iid z(fx)";
        for (const auto& r : iid) std::cerr << " " << r["z"]["fx"];
        std::cerr << "\n";
        runs.push_back(run);
      }
    }
  }
  std::cout << json{{"runs", runs}}.dump(1) << "\n";
  return 0;
}
