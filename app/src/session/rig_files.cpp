#include "session/rig_files.hpp"

#include "cli/cli_common.hpp"

#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/target_detection.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cctype>
#include <fstream>

namespace robocal::app {

namespace fs = std::filesystem;

nlohmann::json pose_to_json(const Eigen::Isometry3d& pose) {
  const Eigen::Vector3d r = vision::rvec_of(pose);
  const Eigen::Vector3d t = pose.translation();
  return {{"rvec", {r.x(), r.y(), r.z()}}, {"tvec", {t.x(), t.y(), t.z()}}};
}

nlohmann::json matrix_to_json(const Eigen::MatrixXd& m) {
  nlohmann::json rows = nlohmann::json::array();
  for (int i = 0; i < m.rows(); ++i) {
    nlohmann::json row = nlohmann::json::array();
    for (int j = 0; j < m.cols(); ++j) row.push_back(m(i, j));
    rows.push_back(row);
  }
  return rows;
}

nlohmann::json pose_measurement_to_json(const vision::PoseMeasurement& m) {
  nlohmann::json j = nlohmann::json::object();
  if (m.status != vision::PoseStatus::kOk && m.status != vision::PoseStatus::kMoving) return j;
  j["rig_T_target"] = pose_to_json(m.world_T_target);
  // Full precision (JSON doubles round-trip exactly): what identify reads.
  j["rig_T_target_matrix"] = matrix_to_json(m.world_T_target.matrix().topRows<3>());
  j["covariance"] = matrix_to_json(m.covariance);
  j["covariance_convention"] = "[d_theta (rad); d_t (m)], rig_T_target = [exp(d_theta) R, t + d_t]";
  j["flags"] = {{"ambiguous", m.ambiguous},
                {"few_corners", m.few_corners},
                {"blurred", m.blurred},
                {"moving", m.moving}};
  j["chi2"] = m.chi2;
  j["dof"] = m.dof;
  j["rms_px"] = m.rms_px;
  j["corners"] = m.corners;
  j["motion_chi2"] = m.motion_chi2;
  return j;
}

nlohmann::json rig_to_json(const std::vector<vision::RigCamera>& rig) {
  nlohmann::json cams = nlohmann::json::array();
  for (const auto& c : rig) {
    cams.push_back({{"name", c.name},
                    {"model", std::string(vision::kind_name(c.model.kind))},
                    {"width", c.model.width},
                    {"height", c.model.height},
                    {"params", c.model.params},
                    {"camera_T_rig", pose_to_json(c.camera_T_world)},
                    {"extrinsic_covariance", matrix_to_json(c.extrinsic_covariance)}});
  }
  return cams;
}

namespace {

std::vector<double> numbers(const nlohmann::json& j, size_t n, const std::string& where) {
  if (!j.is_array() || (n > 0 && j.size() != n))
    throw InputError(
        fmt::format("{}: expected {} numbers", where, n > 0 ? std::to_string(n) : "a list of"));
  std::vector<double> out;
  for (const auto& x : j) {
    if (!x.is_number()) throw InputError(where + ": expected numbers");
    out.push_back(x.get<double>());
  }
  return out;
}

// Frame number of `file` for `camera` ("<camera>.<ext>" = 0, "<camera>_<k>.<ext>" = k), or -1.
int frame_number(const fs::path& file, const std::string& camera) {
  std::string ext = file.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char ch) { return std::tolower(ch); });
  static const std::vector<std::string> kExt = {".png", ".tif", ".tiff", ".pgm",
                                                ".bmp", ".jpg", ".jpeg"};
  if (std::find(kExt.begin(), kExt.end(), ext) == kExt.end()) return -1;
  const std::string stem = file.stem().string();
  if (stem == camera) return 0;
  if (stem.size() <= camera.size() + 1 || stem.compare(0, camera.size(), camera) != 0 ||
      stem[camera.size()] != '_')
    return -1;
  const std::string digits = stem.substr(camera.size() + 1);
  if (digits.size() > 6 ||
      !std::all_of(digits.begin(), digits.end(), [](unsigned char ch) { return std::isdigit(ch); }))
    return -1;
  return std::stoi(digits);
}

}  // namespace

std::vector<vision::RigCamera> load_rig_json(const fs::path& path, double* corner_sigma_px) {
  std::ifstream in(path);
  if (!in) throw InputError(path.string() + ": cannot open the rig file");
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(in);
  } catch (const nlohmann::json::parse_error& e) {
    throw InputError(fmt::format("{}: not valid JSON ({})", path.string(), e.what()));
  }
  const std::string f = path.string();
  if (!doc.contains("cameras") || !doc["cameras"].is_array() || doc["cameras"].empty())
    throw InputError(f + ": needs a non-empty \"cameras\" list (a `robocal rig` output)");
  if (corner_sigma_px) *corner_sigma_px = doc.value("corner_sigma_px", 0.0);
  std::vector<vision::RigCamera> rig;
  for (size_t i = 0; i < doc["cameras"].size(); ++i) {
    const auto& j = doc["cameras"][i];
    const std::string where = fmt::format("{}: cameras[{}]", f, i);
    vision::RigCamera c;
    c.name = j.value("name", fmt::format("cam{}", i));
    const auto kind = vision::kind_from_name(j.value("model", std::string()));
    if (!kind) throw InputError(where + ".model: unknown camera model");
    c.model.kind = *kind;
    c.model.width = j.value("width", 0);
    c.model.height = j.value("height", 0);
    c.model.params = numbers(j.value("params", nlohmann::json()), 0, where + ".params");
    const std::string bad = vision::validate_camera(c.model);
    if (!bad.empty()) throw InputError(fmt::format("{}: {}", where, bad));
    if (!j.contains("camera_T_rig")) throw InputError(where + ": missing camera_T_rig");
    const auto r =
        numbers(j["camera_T_rig"].value("rvec", nlohmann::json()), 3, where + ".camera_T_rig.rvec");
    const auto t =
        numbers(j["camera_T_rig"].value("tvec", nlohmann::json()), 3, where + ".camera_T_rig.tvec");
    c.camera_T_world = vision::pose_from_rvec_tvec(Eigen::Vector3d(r[0], r[1], r[2]),
                                                   Eigen::Vector3d(t[0], t[1], t[2]));
    if (j.contains("extrinsic_covariance")) {
      const auto& m = j["extrinsic_covariance"];
      if (!m.is_array() || m.size() != 6)
        throw InputError(where + ".extrinsic_covariance: expected 6 rows of 6 numbers");
      for (int a = 0; a < 6; ++a) {
        const auto row = numbers(m[static_cast<size_t>(a)], 6, where + ".extrinsic_covariance");
        for (int b = 0; b < 6; ++b) c.extrinsic_covariance(a, b) = row[static_cast<size_t>(b)];
      }
    }
    rig.push_back(c);
  }
  return rig;
}

std::vector<ImageSet> scan_image_folder(const fs::path& folder,
                                        const std::vector<std::string>& camera_names) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder.string() + ": not a folder");
  std::vector<fs::path> subs;
  for (const auto& e : fs::directory_iterator(folder, ec))
    if (e.is_directory()) subs.push_back(e.path());
  std::sort(subs.begin(), subs.end());
  if (subs.empty())
    throw InputError(folder.string() + ": no sub-folders (one per view / robot pose expected)");
  std::vector<ImageSet> out;
  for (const auto& sub : subs) {
    ImageSet set;
    set.name = sub.filename().string();
    set.frames_of_camera.resize(camera_names.size());
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(sub, ec))
      if (e.is_regular_file()) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (size_t c = 0; c < camera_names.size(); ++c) {
      std::vector<std::pair<int, fs::path>> frames;
      for (const auto& file : files) {
        const auto frame_no = frame_number(file, camera_names[c]);
        if (frame_no >= 0) frames.emplace_back(frame_no, file);
      }
      std::sort(frames.begin(), frames.end());
      for (const auto& [k, p] : frames) set.frames_of_camera[c].push_back(p);
    }
    out.push_back(set);
  }
  return out;
}

vision::BoardPoints board_points(const vision::TargetBoard& board) {
  vision::BoardPoints pts;
  for (const auto& c : board.corners) pts[c.id] = c.point;
  return pts;
}

vision::CameraFrame detect_frame(const fs::path& image, const vision::RigCamera& cam,
                                 const vision::TargetBoard& board, std::string* problem) {
  static thread_local vision::AprilTagDetector detector;
  vision::CameraFrame frame;
  const vision::LoadedImage img = vision::load_gray_image(image);
  if (!img.error.empty()) {
    *problem = img.error;
    return frame;
  }
  if (img.gray.cols != cam.model.width || img.gray.rows != cam.model.height) {
    *problem =
        fmt::format("{}: image is {}x{} but camera '{}' is calibrated for {}x{}", image.string(),
                    img.gray.cols, img.gray.rows, cam.name, cam.model.width, cam.model.height);
    return frame;
  }
  const vision::TargetDetection det = vision::detect_target(img.gray, board, detector);
  if (det.status == vision::DetectionStatus::kRejected) {
    *problem = fmt::format("{}: target not detected ({})", image.string(), det.reason);
    return frame;
  }
  frame.blur_px = det.edge_blur_px;
  for (size_t i = 0; i < det.corner_ids.size(); ++i)
    frame.corners.push_back({det.corner_ids[i], det.pixels[i], 0.0});
  // Corners of one tag share edge fits: their joint covariance (vision/README.md).
  frame.corner_groups = det.corner_groups;
  return frame;
}

}  // namespace robocal::app
