#pragma once
// Values in the session's JSON files: poses, matrices, parameter vectors. One writer and one
// reader for each, so every file spells a pose or a parameter set the same way.
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>

namespace robocal::app {

// A JSON file; InputError "<path>: missing (<hint>)" or "<path>: not valid JSON (...)".
nlohmann::json read_json_file(const std::filesystem::path& path, const std::string& hint);

// {"rvec": [3], "tvec": [3]} (OpenCV rotation vector, metres).
nlohmann::json pose_to_json(const Eigen::Isometry3d& pose);
// Throws InputError("<where>: expected {"rvec": [3 numbers], "tvec": [3 numbers]}").
Eigen::Isometry3d pose_from_json(const nlohmann::json& j, const std::string& where);

// Rows of numbers.
nlohmann::json matrix_to_json(const Eigen::MatrixXd& m);
nlohmann::json vector_json(const Eigen::VectorXd& v);

// Parameter vector <-> {name: value}; the reader names `where` and the missing parameter.
nlohmann::json params_json(const calib::Mechanism& model, const Eigen::VectorXd& v);
// "length" | "angle" | "scale": how reports name a parameter's unit.
std::string unit_name(calib::ParamUnit unit);
Eigen::VectorXd params_from_json(const calib::Mechanism& model, const nlohmann::json& j,
                                 const std::string& where);

}  // namespace robocal::app
