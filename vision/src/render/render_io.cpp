#include "robocal/vision/render_io.hpp"

#include "models/yaml_util.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/pose.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>

namespace robocal::vision {

namespace {

Eigen::Vector3d vec3(const detail::YamlContext& ctx, const YAML::Node& n, const std::string& key) {
  const std::vector<double> v = ctx.to_doubles(n, key);
  if (v.size() != 3)
    ctx.fail(n, "'" + key + "' must have 3 numbers (got " + std::to_string(v.size()) + ")");
  for (double x : v)
    if (!std::isfinite(x)) ctx.fail(n, "'" + key + "' must be finite");
  return Eigen::Vector3d(v[0], v[1], v[2]);
}

}  // namespace

std::vector<RenderView> parse_render_views(const std::string& text, const std::string& source,
                                           int num_targets) {
  const detail::YamlContext ctx{source};
  const YAML::Node root = detail::load_yaml_text(text, source);
  if (!root || !root.IsMap()) ctx.fail("a views file must be a mapping with a 'views' list");
  ctx.reject_unknown_keys(root, {"views"});
  const YAML::Node views = ctx.require(root, "views");
  if (!views.IsSequence() || views.size() == 0) ctx.fail(views, "'views' must be a non-empty list");
  std::vector<RenderView> out;
  for (const YAML::Node& v : views) {
    if (!v.IsMap()) ctx.fail(v, "each view must be a mapping with 'poses'");
    ctx.reject_unknown_keys(v, {"name", "poses", "occluders", "seed"});
    RenderView view;
    char buf[32];
    std::snprintf(buf, sizeof(buf), "view%03zu", out.size());
    view.name = buf;
    view.seed = out.size() + 1;
    if (const YAML::Node n = v["name"]) {
      view.name = ctx.to_string(n, "name");
      if (view.name.empty() || view.name.find('/') != std::string::npos)
        ctx.fail(n, "view name must be a plain file name");
    }
    if (const YAML::Node n = v["seed"]) {
      const int s = ctx.to_int(n, "seed");
      if (s < 0) ctx.fail(n, "seed must not be negative");
      view.seed = static_cast<std::uint64_t>(s);
    }
    const YAML::Node poses = ctx.require(v, "poses");
    if (!poses.IsSequence()) ctx.fail(poses, "'poses' must be a list (one pose per target)");
    if (static_cast<int>(poses.size()) != num_targets)
      ctx.fail(poses, "view '" + view.name + "' has " + std::to_string(poses.size()) +
                          " poses but there are " + std::to_string(num_targets) + " targets");
    for (const YAML::Node& p : poses) {
      if (!p.IsMap()) ctx.fail(p, "a pose must be a mapping {rvec: [..], t: [..]}");
      ctx.reject_unknown_keys(p, {"rvec", "t"});
      view.camera_T_board.push_back(pose_from_rvec_tvec(vec3(ctx, ctx.require(p, "rvec"), "rvec"),
                                                        vec3(ctx, ctx.require(p, "t"), "t")));
    }
    if (const YAML::Node occs = v["occluders"]) {
      if (!occs.IsSequence()) ctx.fail(occs, "'occluders' must be a list");
      for (const YAML::Node& o : occs) {
        if (!o.IsMap()) ctx.fail(o, "an occluder must be a mapping");
        ctx.reject_unknown_keys(o, {"disc", "rectangle", "level"});
        Occluder occ;
        occ.level = ctx.to_double(ctx.require(o, "level"), "level");
        if (const YAML::Node d = o["disc"]) {
          const auto x = ctx.to_doubles(d, "disc");
          if (x.size() != 3 || !(x[2] > 0)) ctx.fail(d, "disc must be [cx, cy, radius > 0]");
          occ.shape = Occluder::Shape::kDisc;
          occ.center = Eigen::Vector2d(x[0], x[1]);
          occ.radius = x[2];
        } else if (const YAML::Node r = o["rectangle"]) {
          const auto x = ctx.to_doubles(r, "rectangle");
          if (x.size() != 4 || !(x[2] > 0) || !(x[3] > 0))
            ctx.fail(r, "rectangle must be [cx, cy, half_width > 0, half_height > 0]");
          occ.shape = Occluder::Shape::kRectangle;
          occ.center = Eigen::Vector2d(x[0], x[1]);
          occ.half_size = Eigen::Vector2d(x[2], x[3]);
        } else {
          ctx.fail(o, "an occluder needs 'disc' or 'rectangle'");
        }
        view.occluders.push_back(occ);
      }
    }
    out.push_back(std::move(view));
  }
  return out;
}

std::vector<RenderView> load_render_views(const std::filesystem::path& path, int num_targets) {
  return parse_render_views(detail::read_text_file(path), path.string(), num_targets);
}

namespace {

nlohmann::json pose_json(const Eigen::Isometry3d& pose) {
  const Eigen::Vector3d r = rvec_of(pose);
  const Eigen::Vector3d t = pose.translation();
  nlohmann::json m = nlohmann::json::array();
  for (int i = 0; i < 4; ++i) {
    nlohmann::json row = nlohmann::json::array();
    for (int j = 0; j < 4; ++j) row.push_back(pose.matrix()(i, j));
    m.push_back(row);
  }
  return {{"rvec", {r.x(), r.y(), r.z()}}, {"t", {t.x(), t.y(), t.z()}}, {"matrix", m}};
}

}  // namespace

std::string render_truth_json(const std::string& image_name, const CameraModel& camera,
                              const std::vector<RenderTarget>& targets, const RenderOptions& o,
                              const std::vector<CornerTruth>& corners) {
  nlohmann::json doc;
  doc["format"] = "robocal-render-truth-1";
  doc["pixel_convention"] = "opencv_center";
  doc["image"] = image_name;
  doc["camera"] = camera_to_json(camera);
  nlohmann::json tj = nlohmann::json::array();
  for (const RenderTarget& t : targets)
    tj.push_back({{"name", t.board.spec.name},
                  {"type", target_kind_name(t.board.spec.kind)},
                  {"camera_T_board", pose_json(t.camera_T_board)}});
  doc["targets"] = tj;
  nlohmann::json occ = nlohmann::json::array();
  for (const Occluder& oc : o.occluders) {
    if (oc.shape == Occluder::Shape::kDisc) {
      occ.push_back({{"disc", {oc.center.x(), oc.center.y(), oc.radius}}, {"level", oc.level}});
    } else {
      occ.push_back(
          {{"rectangle", {oc.center.x(), oc.center.y(), oc.half_size.x(), oc.half_size.y()}},
           {"level", oc.level}});
    }
  }
  doc["options"] = {{"black_level", o.black_level},
                    {"white_level", o.white_level},
                    {"background_level", o.background_level},
                    {"lighting_gradient", {o.lighting_gradient.x(), o.lighting_gradient.y()}},
                    {"vignetting", o.vignetting},
                    {"blur_sigma", o.blur_sigma},
                    {"read_noise", o.read_noise},
                    {"shot_noise_gain", o.shot_noise_gain},
                    {"bit_depth", o.bit_depth},
                    {"seed", o.seed},
                    {"occluders", occ}};
  nlohmann::json cj = nlohmann::json::array();
  for (const CornerTruth& c : corners) {
    nlohmann::json e = {
        {"target", c.target}, {"id", c.id}, {"visible", c.visible}, {"occluded", c.occluded}};
    if (c.pixel.allFinite()) {
      e["x"] = c.pixel.x();
      e["y"] = c.pixel.y();
    } else {
      e["x"] = nullptr;
      e["y"] = nullptr;
    }
    cj.push_back(e);
  }
  doc["corners"] = cj;
  return doc.dump(1) + "\n";
}

RenderTruth load_render_truth(const std::filesystem::path& path) {
  const std::string text = detail::read_text_file(path);
  RenderTruth t;
  try {
    const nlohmann::json doc = nlohmann::json::parse(text);
    if (doc.at("format") != "robocal-render-truth-1")
      throw FileFormatError(path.string() + ": not a robocal render truth file");
    t.image = doc.at("image").get<std::string>();
    t.camera = camera_from_json(doc.at("camera"), path.string() + ": camera");
    for (const auto& tj : doc.at("targets")) {
      t.target_names.push_back(tj.at("name").get<std::string>());
      const auto r = tj.at("camera_T_board").at("rvec").get<std::vector<double>>();
      const auto tr = tj.at("camera_T_board").at("t").get<std::vector<double>>();
      if (r.size() != 3 || tr.size() != 3) throw FileFormatError(path.string() + ": bad pose");
      t.camera_T_board.push_back(pose_from_rvec_tvec(Eigen::Vector3d(r[0], r[1], r[2]),
                                                     Eigen::Vector3d(tr[0], tr[1], tr[2])));
    }
    for (const auto& cj : doc.at("corners")) {
      CornerTruth c;
      c.target = cj.at("target").get<int>();
      c.id = cj.at("id").get<int>();
      c.visible = cj.at("visible").get<bool>();
      c.occluded = cj.at("occluded").get<bool>();
      if (cj.at("x").is_null()) {
        c.pixel = Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
      } else {
        c.pixel = Eigen::Vector2d(cj.at("x").get<double>(), cj.at("y").get<double>());
      }
      t.corners.push_back(c);
    }
  } catch (const nlohmann::json::exception& e) {
    throw FileFormatError(path.string() + ": invalid render truth file: " + e.what());
  }
  return t;
}

}  // namespace robocal::vision
