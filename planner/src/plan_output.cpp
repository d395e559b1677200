// Plan files (YAML) and SVG previews (see plan_output.hpp).
#include "robocal/planner/plan_output.hpp"

#include "robocal/core/files.hpp"
#include "robocal/core/yaml.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace robocal::planner {
namespace {

std::string num(double v) {
  return fmt::format("{:.9g}", v);
}

std::string list(const Eigen::VectorXd& v) {
  std::ostringstream s;
  s << "[";
  for (Eigen::Index i = 0; i < v.size(); ++i) s << (i > 0 ? ", " : "") << num(v(i));
  s << "]";
  return s.str();
}

std::string xy(const Eigen::Vector2d& p) {
  return fmt::format("[{:.2f}, {:.2f}]", p.x(), p.y());
}

}  // namespace

std::string plan_to_yaml(const calib::Mechanism& model, const Cell& cell, const PlanResult& plan,
                         const PlanOptions& options) {
  std::ostringstream y;
  y << "# Measurement plan (robocal plan). Poses are in motion order; 'actuators' are the "
       "commands\n"
       "# (actuator readings, robot file units). Pixels: OpenCV convention.\n";
  y << "robot: " << model.name << "\n";
  y << "robot_file: " << model.source << "\n";
  y << "cell: " << cell.source << "\n";
  y << "measured_frame: " << model.bodies[static_cast<std::size_t>(plan.frame)].name << "\n";
  y << "status: "
    << (plan.status == PlanStatus::kOk            ? "ok"
        : plan.status == PlanStatus::kNotAccepted ? "not_accepted"
                                                  : "infeasible")
    << "\n";
  y << "selection:\n";
  y << "  index: " << to_string(options.selection.index) << "\n";
  y << "  candidates_sampled: " << plan.counts.evaluated << "\n";
  y << "  candidates_feasible: " << plan.counts.feasible << "\n";
  y << "  condition_number: " << num(plan.selection.values.condition_number) << "\n";
  y << "  max_condition: " << num(options.selection.max_condition) << "\n";
  y << "  accepted: " << (plan.selection.accepted ? "true" : "false") << "\n";
  y << "  O: [" << num(plan.selection.values.o[0]) << ", " << num(plan.selection.values.o[1])
    << ", " << num(plan.selection.values.o[2]) << ", " << num(plan.selection.values.o[3]) << ", "
    << num(plan.selection.values.o[4]) << "]\n";
  y << "predicted_accuracy:  # 1-sigma position error of the measured frame over the working "
       "volume\n";
  y << "  position_rms_m: " << num(plan.selection.predicted_rms) << "\n";
  y << "  position_max_m: " << num(plan.selection.predicted_max) << "\n";
  y << "  measurement_sigma: {position_m: " << num(options.observability.position_sigma)
    << ", rotation_rad: " << num(options.observability.rotation_sigma) << "}\n";
  y << "tour:\n  length: " << num(plan.tour.length)
    << "\n  nearest_neighbour_length: " << num(plan.tour.nearest_neighbour_length)
    << "\n  segments_checked: " << plan.tour.segments_checked << "\n";
  y << "poses:\n";
  for (const PlannedPose& p : plan.poses) {
    y << "  - id: " << p.id << "\n";
    y << "    actuators: " << list(p.readings) << "\n";
    y << "    position: " << list(p.candidate.world_T_frame.translation()) << "\n";
    y << "    cameras:\n";
    for (std::size_t c = 0; c < cell.cameras.size() && c < p.candidate.views.size(); ++c) {
      const CameraView& v = p.candidate.views[c];
      y << "      " << cell.cameras[c].name << ": {visible: " << (v.visible ? "true" : "false")
        << ", centre: " << xy(v.centre) << ", outline: [" << xy(v.outline[0]) << ", "
        << xy(v.outline[1]) << ", " << xy(v.outline[2]) << ", " << xy(v.outline[3])
        << "], size_px: " << fmt::format("{:.1f}", v.image_size)
        << ", incidence_deg: " << fmt::format("{:.1f}", v.incidence * 180 / M_PI) << "}\n";
    }
  }
  return y.str();
}

std::string plan_to_svg(const Cell& cell, const PlanResult& plan) {
  // Extent: candidates, cameras, obstacles, workspace.
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = Eigen::Vector3d::Constant(-1e300);
  auto grow = [&](const Eigen::Vector3d& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  };
  for (const Candidate& c : plan.pool) grow(c.world_T_frame.translation());
  for (const CellCamera& c : cell.cameras) grow(c.world_T_camera.translation());
  for (const Obstacle& o : cell.obstacles) grow(o.world_T_obstacle.translation());
  if (cell.workspace.declared) {
    grow(cell.workspace.min);
    grow(cell.workspace.max);
  }
  if (lo.x() > hi.x()) {
    lo.setConstant(-1);
    hi.setConstant(1);
  }
  const double pad = 0.1 * (hi - lo).maxCoeff() + 0.05;
  lo.array() -= pad;
  hi.array() += pad;
  const double panel = 420.0;
  const double scale = panel / std::max({hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z()});
  std::ostringstream s;
  s << R"(<svg xmlns="http://www.w3.org/2000/svg" width=")" << 2 * panel + 60 << R"(" height=")"
    << panel + 70 << R"(" font-family="sans-serif" font-size="11">)"
    << "\n";
  s << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  // Views: 0 = top (x right, y up), 1 = side (x right, z up).
  for (int view = 0; view < 2; ++view) {
    const double ox = 20 + view * (panel + 20), oy = 40;
    const int vy = view == 0 ? 1 : 2;
    auto X = [&](const Eigen::Vector3d& p) { return ox + (p.x() - lo.x()) * scale; };
    auto Y = [&](const Eigen::Vector3d& p) { return oy + panel - (p(vy) - lo(vy)) * scale; };
    s << "<text x=\"" << ox << "\" y=\"" << oy - 8 << "\">"
      << (view == 0 ? "top view (x, y)" : "side view (x, z)") << "</text>\n";
    s << "<rect x=\"" << ox << "\" y=\"" << oy << "\" width=\"" << panel << "\" height=\"" << panel
      << "\" fill=\"none\" stroke=\"#ccc\"/>\n";
    if (cell.workspace.declared) {
      const Eigen::Vector3d& a = cell.workspace.min;
      const Eigen::Vector3d& b = cell.workspace.max;
      s << "<rect x=\"" << X(a) << "\" y=\"" << Y(b) << "\" width=\"" << (b.x() - a.x()) * scale
        << "\" height=\"" << (b(vy) - a(vy)) * scale
        << "\" fill=\"none\" stroke=\"green\" stroke-dasharray=\"4,3\"/>\n";
    }
    for (const Obstacle& o : cell.obstacles) {
      // Outline: the projected extent of the obstacle's corners (boxes) or its radius.
      Eigen::Vector3d h = Eigen::Vector3d::Zero();
      if (o.kind == ObstacleKind::kBox) h = 0.5 * o.size;
      if (o.kind == ObstacleKind::kSphere) h.setConstant(o.radius);
      if (o.kind == ObstacleKind::kCylinder)
        h = Eigen::Vector3d(o.radius, o.radius, 0.5 * o.length);
      Eigen::Vector3d mn = Eigen::Vector3d::Constant(1e300), mx = -mn;
      if (o.kind == ObstacleKind::kMesh) {
        for (const Eigen::Vector3d& v : o.vertices) {
          mn = mn.cwiseMin(o.world_T_obstacle * v);
          mx = mx.cwiseMax(o.world_T_obstacle * v);
        }
      } else {
        const Eigen::Vector3d w = o.world_T_obstacle.linear().cwiseAbs() * h;
        mn = o.world_T_obstacle.translation() - w;
        mx = o.world_T_obstacle.translation() + w;
      }
      s << "<rect x=\"" << X(mn) << "\" y=\"" << Y(mx) << "\" width=\"" << (mx.x() - mn.x()) * scale
        << "\" height=\"" << (mx(vy) - mn(vy)) * scale
        << "\" fill=\"#f4a\" fill-opacity=\"0.3\" stroke=\"#c06\"/>\n";
      s << "<text x=\"" << X(mn) << "\" y=\"" << Y(mx) - 2 << "\" fill=\"#c06\">" << o.name
        << "</text>\n";
    }
    for (const CellCamera& c : cell.cameras) {
      const Eigen::Vector3d eye = c.world_T_camera.translation();
      const double depth = 0.4 * (hi - lo).maxCoeff();
      const double fx = c.model.params[0];
      const double hw = 0.5 * c.model.width / fx;
      for (const double sx : {-hw, hw}) {
        const Eigen::Vector3d far = c.world_T_camera * Eigen::Vector3d(sx * depth, 0, depth);
        s << "<line x1=\"" << X(eye) << "\" y1=\"" << Y(eye) << "\" x2=\"" << X(far) << "\" y2=\""
          << Y(far) << "\" stroke=\"#36c\" stroke-opacity=\"0.6\"/>\n";
      }
      s << "<circle cx=\"" << X(eye) << "\" cy=\"" << Y(eye) << "\" r=\"5\" fill=\"#36c\"/>";
      s << "<text x=\"" << X(eye) + 6 << "\" y=\"" << Y(eye) - 6 << "\" fill=\"#36c\">" << c.name
        << "</text>\n";
    }
    for (const Candidate& c : plan.pool)
      s << "<circle cx=\"" << X(c.world_T_frame.translation()) << "\" cy=\""
        << Y(c.world_T_frame.translation()) << "\" r=\"1.2\" fill=\"#bbb\"/>";
    s << "\n<polyline fill=\"none\" stroke=\"#e80\" stroke-width=\"1.2\" points=\"";
    for (const PlannedPose& p : plan.poses)
      s << X(p.candidate.world_T_frame.translation()) << ","
        << Y(p.candidate.world_T_frame.translation()) << " ";
    s << "\"/>\n";
    for (std::size_t k = 0; k < plan.poses.size(); ++k) {
      const Eigen::Vector3d p = plan.poses[k].candidate.world_T_frame.translation();
      s << "<circle cx=\"" << X(p) << "\" cy=\"" << Y(p) << "\" r=\"3\" fill=\"#d30\"/>";
      s << "<text x=\"" << X(p) + 4 << "\" y=\"" << Y(p) - 3 << "\" font-size=\"8\">" << k + 1
        << "</text>\n";
    }
  }
  s << "<text x=\"20\" y=\"" << panel + 60 << "\">" << plan.poses.size()
    << " planned poses (red, numbered in motion order), " << plan.pool.size()
    << " feasible candidates (grey), cameras (blue), obstacles (pink), workspace (green)</text>\n";
  s << "</svg>\n";
  return s.str();
}

std::vector<Eigen::VectorXd> read_plan_actuators(const std::string& path) {
  const YAML::Node root = core::load_yaml_text(core::read_text_file(path), path);
  const YAML::Node poses = root["poses"];
  if (!poses || !poses.IsSequence())
    throw core::InputError(path + ": no 'poses:' list (not a plan file)");
  std::vector<Eigen::VectorXd> out;
  for (const YAML::Node& p : poses) {
    const YAML::Node a = p["actuators"];
    const std::string where = path + ":" + std::to_string(p.Mark().line + 1);
    if (!a || !a.IsSequence() || a.size() == 0)
      throw core::InputError(where + ": pose without 'actuators: [...]'");
    Eigen::VectorXd x(static_cast<Eigen::Index>(a.size()));
    for (std::size_t i = 0; i < a.size(); ++i) {
      try {
        x(static_cast<Eigen::Index>(i)) = a[i].as<double>();
      } catch (const YAML::Exception&) {
        throw core::InputError(where + ": actuator reading '" + a[i].Scalar() +
                               "' is not a number");
      }
    }
    if (!out.empty() && out.front().size() != x.size())
      throw core::InputError(where + ": " + std::to_string(x.size()) +
                             " actuator readings, the first pose has " +
                             std::to_string(out.front().size()));
    out.push_back(x);
  }
  return out;
}

}  // namespace robocal::planner
