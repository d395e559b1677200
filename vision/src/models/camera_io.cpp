#include "robocal/vision/camera_io.hpp"

#include "models/yaml_util.hpp"

#include <sstream>

namespace robocal::vision {

CameraModel parse_camera_yaml(const std::string& text, const std::string& source) {
  const detail::YamlContext ctx{source};
  const YAML::Node root = detail::load_yaml_text(text, source);
  if (!root || !root.IsMap()) ctx.fail("a camera file must be a YAML mapping (model, width, ...)");
  ctx.reject_unknown_keys(root, {"model", "width", "height", "fx", "fy", "cx", "cy", "distortion",
                                 "pixel_convention", "name", "calibration"});
  CameraModel cam;
  const YAML::Node model = ctx.require(root, "model");
  const auto kind = kind_from_name(ctx.to_string(model, "model"));
  if (!kind)
    ctx.fail(model, "unknown camera model '" + model.Scalar() +
                        "' (expected pinhole_radtan, pinhole_rational or fisheye_kb4)");
  cam.kind = *kind;
  if (const YAML::Node conv = root["pixel_convention"]) {
    if (ctx.to_string(conv, "pixel_convention") != "opencv_center")
      ctx.fail(conv,
               "pixel_convention must be 'opencv_center' ((0,0) = centre of the top-left "
               "pixel); convert other conventions before writing the file");
  }
  const YAML::Node w = ctx.require(root, "width");
  const YAML::Node h = ctx.require(root, "height");
  cam.width = ctx.to_int(w, "width");
  cam.height = ctx.to_int(h, "height");
  if (cam.width <= 0) ctx.fail(w, "width must be positive");
  if (cam.height <= 0) ctx.fail(h, "height must be positive");
  const int n_dist = num_params(cam.kind) - 4;
  cam.params.assign(static_cast<size_t>(n_dist + 4), 0.0);
  const char* names[4] = {"fx", "fy", "cx", "cy"};
  for (int i = 0; i < 4; ++i) {
    const YAML::Node n = ctx.require(root, names[i]);
    const double v = ctx.to_double(n, names[i]);
    if (!std::isfinite(v)) ctx.fail(n, std::string(names[i]) + " must be finite");
    if (i < 2 && !(v > 0.0)) ctx.fail(n, std::string(names[i]) + " must be positive");
    cam.params[static_cast<size_t>(i)] = v;
  }
  const YAML::Node dist = ctx.require(root, "distortion");
  const std::vector<double> d = ctx.to_doubles(dist, "distortion");
  if (static_cast<int>(d.size()) != n_dist)
    ctx.fail(dist, std::string(kind_name(cam.kind)) + " needs " + std::to_string(n_dist) +
                       " distortion coefficients, got " + std::to_string(d.size()));
  for (size_t i = 0; i < d.size(); ++i) {
    if (!std::isfinite(d[i])) ctx.fail(dist, "distortion coefficients must be finite");
    cam.params[i + 4] = d[i];
  }
  return cam;
}

CameraModel load_camera_file(const std::filesystem::path& path) {
  return parse_camera_yaml(detail::read_text_file(path), path.string());
}

std::string camera_to_yaml(const CameraModel& camera, const std::string& name) {
  std::ostringstream out;
  out.precision(17);
  out << "# robocal camera model\n";
  out << "# pixel convention: OpenCV, (0,0) = centre of the top-left pixel\n";
  if (!name.empty()) out << "name: \"" << name << "\"\n";
  out << "model: " << kind_name(camera.kind) << "\n";
  out << "pixel_convention: opencv_center\n";
  out << "width: " << camera.width << "\n";
  out << "height: " << camera.height << "\n";
  const char* names[4] = {"fx", "fy", "cx", "cy"};
  for (size_t i = 0; i < 4 && i < camera.params.size(); ++i)
    out << names[i] << ": " << camera.params[i] << "\n";
  out << "distortion: [";
  for (size_t i = 4; i < camera.params.size(); ++i) out << (i > 4 ? ", " : "") << camera.params[i];
  out << "]\n";
  return out.str();
}

void save_camera_file(const CameraModel& camera, const std::filesystem::path& path,
                      const std::string& name) {
  detail::write_text_file_atomic(path, camera_to_yaml(camera, name));
}

nlohmann::json camera_to_json(const CameraModel& camera) {
  return {{"model", std::string(kind_name(camera.kind))},
          {"width", camera.width},
          {"height", camera.height},
          {"params", camera.params}};
}

CameraModel camera_from_json(const nlohmann::json& j, const std::string& where) {
  CameraModel camera;
  if (!j.is_object()) throw FileFormatError(where + ": a camera is an object {model, width, ...}");
  const auto kind = kind_from_name(j.value("model", std::string()));
  if (!kind) throw FileFormatError(where + ".model: unknown camera model");
  camera.kind = *kind;
  try {
    camera.width = j.value("width", 0);
    camera.height = j.value("height", 0);
    camera.params = j.value("params", std::vector<double>());
  } catch (const nlohmann::json::exception&) {
    throw FileFormatError(where + ": width, height must be integers and params numbers");
  }
  const std::string problem = validate_camera(camera);
  if (!problem.empty()) throw FileFormatError(where + ": " + problem);
  return camera;
}

}  // namespace robocal::vision
