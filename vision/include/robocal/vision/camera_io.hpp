#pragma once
// Camera files (YAML). Example:
//   # pixel convention: OpenCV, (0,0) = centre of the top-left pixel
//   model: pinhole_radtan        # pinhole_radtan | pinhole_rational | fisheye_kb4
//   width: 2448
//   height: 2048
//   fx: 2400.0
//   fy: 2400.0
//   cx: 1223.5
//   cy: 1023.5
//   distortion: [k1, k2, p1, p2, k3]   # 5 (radtan), 8 (rational: + k4 k5 k6), 4 (fisheye k1..k4)
//   pixel_convention: opencv_center   # optional; the only accepted value
//   name: left                        # optional
//   calibration: {...}                # optional free-form block (ignored by the loader)
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/errors.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>

namespace robocal::vision {

// Throws FileFormatError("<file>:<line>: <problem>") on any error.
CameraModel load_camera_file(const std::filesystem::path& path);
// `source` names the text in error messages (a file name).
CameraModel parse_camera_yaml(const std::string& text, const std::string& source);

// Text of a camera file; doubles are written with 17 significant digits (exact round trip).
std::string camera_to_yaml(const CameraModel& camera, const std::string& name = {});
// Writes atomically (temporary file + rename). Throws FileFormatError if it cannot write.
void save_camera_file(const CameraModel& camera, const std::filesystem::path& path,
                      const std::string& name = {});

// The camera as a JSON object {"model", "width", "height", "params"} (the project's JSON files
// that hold a camera: rig files, render truth, a simulated session's truth). Params in the
// model's order (camera_models.hpp), exact doubles.
nlohmann::json camera_to_json(const CameraModel& camera);
// Reads that object; throws FileFormatError("<where>: <problem>") for an unknown model, a
// missing field or parameters that do not fit the model.
CameraModel camera_from_json(const nlohmann::json& j, const std::string& where);

}  // namespace robocal::vision
