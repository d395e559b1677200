#include "robocal/vision/hand_eye_io.hpp"

#include "robocal/core/files.hpp"
#include "robocal/core/yaml.hpp"

#include <fmt/format.h>

#include <cmath>
#include <map>
#include <sstream>

namespace robocal::vision {

namespace fs = std::filesystem;

Eigen::Isometry3d read_flange_pose(const core::YamlContext& ctx, const YAML::Node& map) {
  if (!map.IsMap()) ctx.fail(map, "a flange pose must be a mapping of x y z qx qy qz qw");
  ctx.reject_unknown_keys(map, {"x", "y", "z", "qx", "qy", "qz", "qw"});
  const Eigen::Vector3d t(ctx.required<double>(map, "x"), ctx.required<double>(map, "y"),
                          ctx.required<double>(map, "z"));
  const Eigen::Quaterniond q(ctx.required<double>(map, "qw"), ctx.required<double>(map, "qx"),
                             ctx.required<double>(map, "qy"), ctx.required<double>(map, "qz"));
  if (!t.allFinite() || !q.coeffs().allFinite())
    ctx.fail(map, "the pose has a value that is not finite");
  // A controller writes unit quaternions to a few digits; anything else is not a rotation
  // (Euler angles or a rotation vector under the q keys).
  if (std::abs(q.norm() - 1.0) > 1e-3)
    ctx.fail(map, fmt::format("the quaternion (qx qy qz qw) has length {:.4f}, not 1: it is not "
                              "a rotation (Euler angles or a rotation vector under the q keys?)",
                              q.norm()));
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = q.normalized().toRotationMatrix();
  pose.translation() = t;
  return pose;
}

namespace {

Eigen::Isometry3d pose_from_file(const fs::path& file) {
  const core::YamlContext ctx{file.string()};
  return read_flange_pose(ctx, core::load_yaml_text(core::read_text_file(file), file.string()));
}

// The poses of a pairing list, by the image's file name.
std::map<std::string, Eigen::Isometry3d> read_pairing_list(const fs::path& list) {
  const core::YamlContext ctx{list.string()};
  const YAML::Node root = core::load_yaml_text(core::read_text_file(list), list.string());
  if (!root.IsSequence())
    ctx.fail(root, "a pose list must be a sequence of {image: FILE, pose: FILE or mapping}");
  std::map<std::string, Eigen::Isometry3d> out;
  for (const YAML::Node& entry : root) {
    if (!entry.IsMap()) ctx.fail(entry, "each entry must be a mapping {image, pose}");
    ctx.reject_unknown_keys(entry, {"image", "pose"});
    const std::string image = fs::path(ctx.required<std::string>(entry, "image")).filename();
    const YAML::Node pose = ctx.require(entry, "pose");
    const Eigen::Isometry3d p = pose.IsScalar()
                                    ? pose_from_file(list.parent_path() / pose.as<std::string>())
                                    : read_flange_pose(ctx, pose);
    if (!out.emplace(image, p).second)
      ctx.fail(entry, fmt::format("image '{}' is listed twice", image));
  }
  return out;
}

std::string yaml_number(double v) {
  return fmt::format("{:.9g}", v);
}

// A YAML single-quoted scalar (a quote is written twice).
std::string quoted(const std::string& text) {
  std::string out = "'";
  for (char c : text) out += c == '\'' ? std::string("''") : std::string(1, c);
  return out + "'";
}

std::string transform_yaml(const std::string& key, const std::string& parent,
                           const std::string& child, const Eigen::Isometry3d& pose,
                           const core::PoseCovariance& cov) {
  const Eigen::Quaterniond q(pose.linear());
  const Eigen::Vector3d t = pose.translation();
  std::string out = fmt::format("{}:\n  parent: {}\n  child: {}\n", key, parent, child);
  out += fmt::format("  translation_m: [{}, {}, {}]\n", yaml_number(t.x()), yaml_number(t.y()),
                     yaml_number(t.z()));
  out += fmt::format("  quaternion_xyzw: [{}, {}, {}, {}]\n", yaml_number(q.x()),
                     yaml_number(q.y()), yaml_number(q.z()), yaml_number(q.w()));
  out += fmt::format("  sigma_position_m: [{:.3g}, {:.3g}, {:.3g}]\n", std::sqrt(cov(0, 0)),
                     std::sqrt(cov(1, 1)), std::sqrt(cov(2, 2)));
  out += fmt::format("  sigma_rotation_rad: [{:.3g}, {:.3g}, {:.3g}]\n", std::sqrt(cov(3, 3)),
                     std::sqrt(cov(4, 4)), std::sqrt(cov(5, 5)));
  out += "  covariance_convention: position_first_world_frame  # [dp; dphi], 6x6 row-major\n";
  out += "  covariance: [";
  for (int i = 0; i < 36; ++i) out += (i ? ", " : "") + fmt::format("{:.6g}", cov(i / 6, i % 6));
  out += "]\n";
  return out;
}

}  // namespace

Eigen::Isometry3d read_flange_pose_file(const fs::path& file) {
  return pose_from_file(file);
}

std::vector<Eigen::Isometry3d> read_flange_poses(const fs::path& poses,
                                                 const std::vector<fs::path>& images) {
  std::vector<Eigen::Isometry3d> out;
  if (fs::is_directory(poses)) {
    for (const fs::path& image : images) {
      const fs::path file = poses / (image.stem().string() + ".yaml");
      if (!fs::exists(file))
        throw core::InputError(fmt::format("{}: no flange pose for this image (expected {})",
                                           image.string(), file.string()));
      out.push_back(pose_from_file(file));
    }
    return out;
  }
  if (!fs::exists(poses))
    throw core::InputError(fmt::format("{}: no such pose file or folder", poses.string()));
  const auto listed = read_pairing_list(poses);
  for (const fs::path& image : images) {
    const auto it = listed.find(image.filename().string());
    if (it == listed.end())
      throw core::InputError(
          fmt::format("{}: no flange pose for this image in {}", image.string(), poses.string()));
    out.push_back(it->second);
  }
  return out;
}

std::string ros2_static_transform(const Eigen::Isometry3d& parent_T_child,
                                  const std::string& parent, const std::string& child) {
  const Eigen::Quaterniond q(parent_T_child.linear());
  const Eigen::Vector3d t = parent_T_child.translation();
  return fmt::format(
      "ros2 run tf2_ros static_transform_publisher --x {} --y {} --z {} --qx {} --qy {} --qz {} "
      "--qw {} --frame-id {} --child-frame-id {}",
      yaml_number(t.x()), yaml_number(t.y()), yaml_number(t.z()), yaml_number(q.x()),
      yaml_number(q.y()), yaml_number(q.z()), yaml_number(q.w()), parent, child);
}

std::string hand_eye_to_yaml(const HandEyeResult& r) {
  const bool fixed = r.mount == HandEyeMount::kFixedCamera;
  const std::string camera_parent = fixed ? "base" : "flange";
  const std::string target_parent = fixed ? "flange" : "base";
  std::string out = "# robocal handeye: the camera and the board relative to the robot\n";
  out += fmt::format("mount: {}\n", hand_eye_mount_name(r.mount));
  out += transform_yaml("camera", camera_parent, "camera", r.camera_pose, r.camera_pose_covariance);
  out += transform_yaml("target", target_parent, "target", r.target_pose, r.target_pose_covariance);
  out += fmt::format("reprojection_rms_px: {:.4f}\n", r.rms_px);
  out += fmt::format("residual_sigma_px: {:.4f}\n", r.residual_sigma_px);
  out += fmt::format("rotation_consistency_deg: {:.4f}\n", r.rotation_mismatch_deg);
  out += fmt::format("corners_used: {}\n", r.corners_used);
  out += "views:\n";
  for (const HandEyeViewReport& v : r.views) {
    out += fmt::format("  - {{image: {}, used: {}, corners: {}", quoted(v.name), v.used, v.corners);
    if (std::isfinite(v.rms_px)) out += fmt::format(", rms_px: {:.4f}", v.rms_px);
    if (!v.rejection.empty()) out += fmt::format(", reason: {}", quoted(v.rejection));
    out += "}\n";
  }
  out += "ros2_static_transforms:\n";
  out += fmt::format("  - \"{}\"\n", ros2_static_transform(r.camera_pose, camera_parent, "camera"));
  out += fmt::format("  - \"{}\"\n", ros2_static_transform(r.target_pose, target_parent, "target"));
  return out;
}

}  // namespace robocal::vision
