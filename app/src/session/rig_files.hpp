#pragma once
// Files of `robocal rig` and `robocal measure`: the rig JSON (written by `rig`, read by
// `measure`) and image folders of per-view / per-pose sub-folders. Format: vision/README_rig.md.
#include "robocal/vision/observations.hpp"
#include "robocal/vision/pose_measurement.hpp"
#include "robocal/vision/rig_calibration.hpp"
#include "robocal/vision/target.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace robocal::app {

// Rig JSON <-> rig. corner_sigma_px: the calibration's RMS residual (0 when absent).
nlohmann::json rig_to_json(const std::vector<vision::RigCamera>& rig);
std::vector<vision::RigCamera> load_rig_json(const std::filesystem::path& path,
                                             double* corner_sigma_px);

// One sub-folder (a view or a robot pose) of an image folder: per camera, the image files of
// its frames ("<camera>.<ext>" or "<camera>_<k>.<ext>", k = 0, 1, ... in order).
struct ImageSet {
  std::string name;                                                  // sub-folder name
  std::vector<std::vector<std::filesystem::path>> frames_of_camera;  // [camera][frame]
};
// Sub-folders sorted by name. Throws InputError if the folder is missing or has no sub-folders.
std::vector<ImageSet> scan_image_folder(const std::filesystem::path& folder,
                                        const std::vector<std::string>& camera_names);

// Detects the target in one image for one camera. On a problem (unreadable, size differs from
// the camera file, target not found) returns an empty frame and sets *problem.
vision::CameraFrame detect_frame(const std::filesystem::path& image, const vision::RigCamera& cam,
                                 const vision::TargetBoard& board, std::string* problem);

vision::BoardPoints board_points(const vision::TargetBoard& board);

nlohmann::json pose_to_json(const Eigen::Isometry3d& pose);
nlohmann::json matrix_to_json(const Eigen::MatrixXd& m);

// The measured board pose of one robot pose as `robocal measure` writes it (app/SESSION.md,
// results/measured_poses.json): rig_T_target (rvec/tvec), rig_T_target_matrix (3x4, full
// precision), the 6x6 covariance and its convention, quality flags, chi2, dof, rms_px, corners,
// motion_chi2. Only for a measurement with a pose (status kOk or kMoving); else an empty object.
nlohmann::json pose_measurement_to_json(const vision::PoseMeasurement& m);

}  // namespace robocal::app
