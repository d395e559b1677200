#include "session/json_values.hpp"

#include "cli/cli_common.hpp"

#include "robocal/vision/pose.hpp"

#include <fmt/core.h>

#include <fstream>
#include <stdexcept>
#include <vector>

namespace robocal::app {

nlohmann::json read_json_file(const std::filesystem::path& path, const std::string& hint) {
  std::ifstream in(path);
  if (!in) throw InputError(fmt::format("{}: missing ({})", path.string(), hint));
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: not valid JSON ({})", path.string(), e.what()));
  }
}

nlohmann::json pose_to_json(const Eigen::Isometry3d& pose) {
  const Eigen::Vector3d r = vision::rvec_of(pose);
  const Eigen::Vector3d t = pose.translation();
  return {{"rvec", {r.x(), r.y(), r.z()}}, {"tvec", {t.x(), t.y(), t.z()}}};
}

Eigen::Isometry3d pose_from_json(const nlohmann::json& j, const std::string& where) {
  try {
    const auto r = j.at("rvec").get<std::vector<double>>();
    const auto t = j.at("tvec").get<std::vector<double>>();
    if (r.size() != 3 || t.size() != 3) throw std::invalid_argument("size");
    return vision::pose_from_rvec_tvec(Eigen::Vector3d(r[0], r[1], r[2]),
                                       Eigen::Vector3d(t[0], t[1], t[2]));
  } catch (const std::exception&) {
    throw InputError(where + ": expected {\"rvec\": [3 numbers], \"tvec\": [3 numbers]}");
  }
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

nlohmann::json vector_json(const Eigen::VectorXd& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

nlohmann::json params_json(const calib::Mechanism& model, const Eigen::VectorXd& v) {
  nlohmann::json j = nlohmann::json::object();
  for (std::size_t i = 0; i < model.parameters.size(); ++i)
    j[model.parameters[i].name] = v[static_cast<Eigen::Index>(i)];
  return j;
}

std::string unit_name(calib::ParamUnit unit) {
  switch (unit) {
    case calib::ParamUnit::kLength:
      return "length";
    case calib::ParamUnit::kAngle:
      return "angle";
    default:
      return "scale";
  }
}

Eigen::VectorXd params_from_json(const calib::Mechanism& model, const nlohmann::json& j,
                                 const std::string& where) {
  Eigen::VectorXd v = model.nominal_parameters();
  for (std::size_t i = 0; i < model.parameters.size(); ++i) {
    const auto& name = model.parameters[i].name;
    if (!j.contains(name) || !j[name].is_number())
      throw InputError(
          fmt::format("{}: no value for parameter '{}' of {}", where, name, model.name));
    v[static_cast<Eigen::Index>(i)] = j[name].get<double>();
  }
  return v;
}

}  // namespace robocal::app
