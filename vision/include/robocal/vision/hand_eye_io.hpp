#pragma once
// The files of a hand-eye calibration: the flange poses a controller reported, one per image, and
// the answer in the forms users paste (YAML with covariance, a ROS static transform).
//
// A flange pose is a YAML mapping with x y z (metres) and qx qy qz qw (the rotation's unit
// quaternion), base -> flange, as ROS and most controllers' tools write it:
//   x: 0.113   y: 0.589   z: 0.653   qx: -0.519   qy: 0.816   qz: 0.093   qw: 0.239
// `--poses` names either a folder with one such file per image (3.png -> 3.yaml) or a YAML list
// pairing them: `- {image: images/3.png, pose: poses/3.yaml}` (paths relative to the list), where
// `pose` may also be the mapping itself.
#include "robocal/core/yaml.hpp"
#include "robocal/vision/hand_eye.hpp"

#include <Eigen/Geometry>

#include <filesystem>
#include <string>
#include <vector>

namespace robocal::vision {

// One flange pose mapping at `node` of the file `ctx` reads (also the `flange_pose` that
// `robocal collect` records in a pose folder's pose.yaml). InputError naming file:line.
Eigen::Isometry3d read_flange_pose(const core::YamlContext& ctx, const YAML::Node& node);

// One flange pose file (InputError naming the file and line: a missing or unknown key, a
// quaternion that is not of unit length).
Eigen::Isometry3d read_flange_pose_file(const std::filesystem::path& file);

// The reported pose of each image, in the images' order. InputError naming the image when its
// pose is missing, and naming the entry when the list refers to an image not given.
std::vector<Eigen::Isometry3d> read_flange_poses(const std::filesystem::path& poses,
                                                 const std::vector<std::filesystem::path>& images);

// The answer as YAML: the mounting, both transforms (parent, child, translation, quaternion
// x y z w, 1-sigma position and rotation), the reprojection figures, every view with why it was
// left out, and the ROS 2 static transform publisher commands.
std::string hand_eye_to_yaml(const HandEyeResult& result);

// "ros2 run tf2_ros static_transform_publisher --x ... --frame-id PARENT --child-frame-id CHILD"
std::string ros2_static_transform(const Eigen::Isometry3d& parent_T_child,
                                  const std::string& parent, const std::string& child);

}  // namespace robocal::vision
