#include "session/results_files.hpp"

#include "cli/cli_common.hpp"
#include "session/json_values.hpp"

#include "robocal/calib/held_out_errors.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/pose_covariance.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/pose.hpp"

#include <fmt/core.h>

#include <map>
#include <set>
#include <stdexcept>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

std::vector<double> numbers(const nlohmann::json& j, std::size_t n, const std::string& where) {
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

Eigen::VectorXd to_vector(const std::vector<double>& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

}  // namespace

// ---- rig.json ---------------------------------------------------------------------------------

nlohmann::json rig_cameras_json(const std::vector<vision::RigCamera>& rig) {
  nlohmann::json cams = nlohmann::json::array();
  for (const auto& c : rig) {
    nlohmann::json j = vision::camera_to_json(c.model);
    j["name"] = c.name;
    j["camera_T_rig"] = pose_to_json(c.camera_T_world);
    j["extrinsic_covariance"] = matrix_to_json(c.extrinsic_covariance);
    cams.push_back(j);
  }
  return cams;
}

nlohmann::json rig_file_json(const vision::RigCalibrationResult& rig, const std::string& reference,
                             const std::string& target, double corner_sigma_px) {
  nlohmann::json doc{{"ok", rig.ok},
                     {"message", rig.message},
                     {"reference", reference},
                     {"target", target},
                     {"rms_px", rig.rms_px},
                     {"variance_factor", rig.variance_factor},
                     {"corner_sigma_px", corner_sigma_px}};
  if (!rig.ok) return doc;
  doc["cameras"] = rig_cameras_json(rig.rig());
  for (std::size_t c = 0; c < rig.cameras.size(); ++c) {
    doc["cameras"][c]["baseline_m"] = rig.cameras[c].baseline_m;
    doc["cameras"][c]["baseline_sigma_m"] = rig.cameras[c].baseline_sigma_m;
  }
  return doc;
}

RigFile read_rig_file(const fs::path& path) {
  if (!fs::exists(path)) throw InputError(path.string() + ": cannot open the rig file");
  const nlohmann::json doc = read_json_file(path, "a rig file");
  const std::string f = path.string();
  if (!doc.contains("cameras") || !doc["cameras"].is_array() || doc["cameras"].empty())
    throw InputError(f + ": needs a non-empty \"cameras\" list (a `robocal rig` output)");
  RigFile out;
  out.corner_sigma_px = doc.value("corner_sigma_px", 0.0);
  for (std::size_t i = 0; i < doc["cameras"].size(); ++i) {
    const auto& j = doc["cameras"][i];
    const std::string where = fmt::format("{}: cameras[{}]", f, i);
    vision::RigCamera c;
    c.name = j.value("name", fmt::format("cam{}", i));
    c.model = vision::camera_from_json(j, where);
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
        const auto row =
            numbers(m[static_cast<std::size_t>(a)], 6, where + ".extrinsic_covariance");
        for (int b = 0; b < 6; ++b) c.extrinsic_covariance(a, b) = row[static_cast<std::size_t>(b)];
      }
    }
    out.cameras.push_back(c);
    const auto baseline = j.find("baseline_m");
    out.baseline_m.push_back(baseline != j.end() && baseline->is_number() ? baseline->get<double>()
                                                                          : 0.0);
  }
  return out;
}

// ---- measured_poses.json -----------------------------------------------------------------------

nlohmann::json pose_measurement_json(const std::string& pose, const vision::PoseMeasurement& m,
                                     const std::vector<std::string>& problems, std::size_t frames) {
  nlohmann::json j{{"pose", pose},         {"status", vision::pose_status_name(m.status)},
                   {"usable", m.usable()}, {"message", m.message},
                   {"problems", problems}, {"frames", frames}};
  j.update(pose_measurement_to_json(m));
  return j;
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

void write_measured_poses(const ResultsLayout& results,
                          const std::vector<MeasuredPoseRecord>& poses) {
  nlohmann::json list = nlohmann::json::array();
  for (const auto& p : poses) {
    nlohmann::json j = pose_measurement_json(p.pose, p.measurement, p.problems, p.frames);
    j["timestamp"] = p.timestamp;
    if (p.actuators) j["actuators"] = vector_json(*p.actuators);
    j["used"] = p.excluded.empty();
    if (!p.excluded.empty()) j["excluded"] = p.excluded;
    list.push_back(j);
  }
  write_json({{"poses", list}}, results.measured_poses().string());
}

std::vector<MeasuredPose> read_used_measured_poses(const ResultsLayout& results,
                                                   const std::string& hint) {
  const fs::path path = results.measured_poses();
  const nlohmann::json doc = read_json_file(path, hint);
  std::vector<MeasuredPose> out;
  try {
    for (const auto& p : doc.at("poses")) {
      if (!p.value("used", false)) continue;
      MeasuredPose pose;
      pose.pose = p.at("pose").get<std::string>();
      pose.actuators = to_vector(p.at("actuators").get<std::vector<double>>());
      pose.rms_px = p.value("rms_px", 0.0);
      const auto rows = p.at("rig_T_target_matrix").get<std::vector<std::vector<double>>>();
      const auto cov_rows = p.at("covariance").get<std::vector<std::vector<double>>>();
      if (rows.size() != 3 || cov_rows.size() != 6)
        throw InputError(path.string() + ": pose " + pose.pose +
                         " has a malformed pose or covariance");
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) pose.rig_T_target.matrix()(r, c) = rows.at(r).at(c);
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) pose.covariance(r, c) = cov_rows.at(r).at(c);
      out.push_back(std::move(pose));
    }
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: malformed ({})", path.string(), e.what()));
  } catch (const std::out_of_range& e) {
    throw InputError(fmt::format("{}: malformed ({})", path.string(), e.what()));
  }
  return out;
}

std::vector<calib::PoseMeasurement> to_pose_measurements(const std::vector<MeasuredPose>& poses) {
  std::vector<calib::PoseMeasurement> out;
  out.reserve(poses.size());
  for (const auto& p : poses)
    out.push_back({p.pose,
                   p.actuators,
                   {calib::PoseObservation::with_covariance(p.rig_T_target,
                                                            core::position_first(p.covariance))}});
  return out;
}

// ---- pixel_observations.json -------------------------------------------------------------------

nlohmann::json corner_observations_json(const std::vector<std::vector<vision::CameraFrame>>& frames,
                                        const std::vector<std::string>& camera_names,
                                        double default_sigma, bool skip_empty) {
  nlohmann::json obs = nlohmann::json::array();
  for (std::size_t f = 0; f < frames.size(); ++f)
    for (std::size_t c = 0; c < camera_names.size(); ++c) {
      const auto& frame = frames[f][c];
      if (skip_empty && frame.corners.empty()) continue;
      nlohmann::json corners = nlohmann::json::array();
      for (const auto& o : frame.corners)
        corners.push_back(
            {o.id, o.pixel.x(), o.pixel.y(), o.sigma_px > 0 ? o.sigma_px : default_sigma});
      nlohmann::json entry{{"frame", f}, {"camera", camera_names[c]}, {"corners", corners}};
      // Corners of one tag share edge fits: their joint covariance (px^2, ordered u0 v0 u1 v1 ...
      // like "corners" of the group), as the pose measurement used it.
      if (!frame.corner_groups.empty()) {
        nlohmann::json groups = nlohmann::json::array();
        for (const auto& g : frame.corner_groups)
          groups.push_back(
              {{"corners", g.corner_ids}, {"covariance", matrix_to_json(g.covariance)}});
        entry["corner_groups"] = groups;
      }
      obs.push_back(entry);
    }
  return obs;
}

void write_pixel_observations(const ResultsLayout& results, const PixelObservationsHeader& header,
                              const std::vector<PixelPoseRecord>& poses) {
  nlohmann::json list = nlohmann::json::array();
  for (const auto& p : poses) {
    nlohmann::json pixel{{"pose", p.pose}, {"used", p.used}, {"observations", p.observations}};
    if (p.actuators)
      pixel["actuators"] = vector_json(*p.actuators);
    else
      pixel["excluded"] = p.excluded;
    list.push_back(pixel);
  }
  write_json({{"format", "robocal pixel observations 1 (app/SESSION.md)"},
              {"robot", header.robot_file},
              {"measured_frame", header.measured_frame},
              {"rig", ResultsLayout::kRig},
              {"target", header.target},
              {"pixel_convention", "OpenCV: (0,0) = centre of the top-left pixel"},
              {"corner_format", "[board corner id, u (px), v (px), sigma (px)]"},
              {"poses", list}},
             results.pixel_observations().string());
}

std::vector<PixelPose> read_used_pixel_poses(const ResultsLayout& results,
                                             const std::vector<std::string>& camera_names,
                                             const std::string& hint) {
  const fs::path ppath = results.pixel_observations();
  const nlohmann::json doc = read_json_file(ppath, hint);
  std::map<std::string, std::size_t> camera_index;
  for (std::size_t c = 0; c < camera_names.size(); ++c) camera_index[camera_names[c]] = c;
  std::vector<PixelPose> poses;
  try {
    for (const auto& p : doc.at("poses")) {
      if (!p.value("used", false)) continue;
      PixelPose pose{p.at("pose").get<std::string>(),
                     to_vector(p.at("actuators").get<std::vector<double>>()),
                     std::vector<vision::CameraFrame>(camera_names.size())};
      for (const auto& obs : p.at("observations")) {
        if (obs.value("frame", 0) != 0) continue;  // settled frames: the first one is used
        const auto name = obs.at("camera").get<std::string>();
        const auto it = camera_index.find(name);
        if (it == camera_index.end())
          throw InputError(fmt::format("{}: pose {} names camera '{}', which {} does not have",
                                       ppath.string(), pose.pose, name, ResultsLayout::kRig));
        auto& frame = pose.cameras[it->second];
        for (const auto& c : obs.at("corners")) {
          const auto v = c.get<std::vector<double>>();
          if (v.size() != 4)
            throw InputError(fmt::format("{}: pose {} camera {}: a corner is not [id, u, v, sigma]",
                                         ppath.string(), pose.pose, name));
          frame.corners.push_back({static_cast<int>(v[0]), Eigen::Vector2d(v[1], v[2]), v[3]});
        }
        for (const auto& g : obs.value("corner_groups", nlohmann::json::array())) {
          vision::CornerGroup group;
          group.corner_ids = g.at("corners").get<std::vector<int>>();
          const auto rows = g.at("covariance").get<std::vector<std::vector<double>>>();
          const auto n = static_cast<Eigen::Index>(2 * group.corner_ids.size());
          if (static_cast<Eigen::Index>(rows.size()) != n)
            throw InputError(
                fmt::format("{}: pose {} camera {}: a corner group's covariance is "
                            "not {}x{}",
                            ppath.string(), pose.pose, name, n, n));
          group.covariance.resize(n, n);
          for (Eigen::Index r = 0; r < n; ++r) {
            const auto& row = rows[static_cast<std::size_t>(r)];
            if (static_cast<Eigen::Index>(row.size()) != n)
              throw InputError(
                  fmt::format("{}: pose {} camera {}: a corner group's covariance "
                              "is not {}x{}",
                              ppath.string(), pose.pose, name, n, n));
            for (Eigen::Index c = 0; c < n; ++c)
              group.covariance(r, c) = row[static_cast<std::size_t>(c)];
          }
          frame.corner_groups.push_back(std::move(group));
        }
      }
      poses.push_back(std::move(pose));
    }
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: malformed ({})", ppath.string(), e.what()));
  }
  return poses;
}

// ---- identification.json ----------------------------------------------------------------------

void write_identification(const ResultsLayout& results, const nlohmann::json& report) {
  write_json(report, results.identification().string());
}

ParameterAccount parameter_account(const nlohmann::json& identification, const std::string& where) {
  // identify's session report holds calib's result under "result"; `robocal identify --json`
  // writes calib's result itself.
  const nlohmann::json& r =
      identification.contains("result") ? identification.at("result") : identification;
  ParameterAccount a;
  try {
    std::set<std::string> identified;
    for (const auto& p : r.at("parameters")) {
      a.names.push_back(p.at("name").get<std::string>());
      const std::string label = p.value("label", std::string());
      a.labels.push_back(label.empty() ? a.names.back() : label);
      a.identified.push_back(p.at("estimated").get<bool>());
      if (a.identified.back()) identified.insert(a.names.back());
    }
    const nlohmann::json& id = r.at("identifiability");
    // The analysis sorts every free parameter (the candidates) into identifiable or held.
    a.counts.total = a.names.size();
    a.counts.free = id.at("identifiable").size() + id.at("held_at_nominal").size();
    a.counts.identified = identified.size();
    if (a.counts.identified > a.counts.free || a.counts.free > a.counts.total)
      throw InputError(fmt::format(
          "{}: {} parameters, {} free (identifiability), {} estimated: the counts do not fit "
          "together",
          where, a.counts.total, a.counts.free, a.counts.identified));
    a.counts.held = a.counts.free - a.counts.identified;
    for (const auto& n : id.at("no_effect"))
      if (identified.count(n.get<std::string>()) == 0) a.no_effect.push_back(n.get<std::string>());
    a.counts.no_effect = a.no_effect.size();
    // A parameter the relinearised solve went on to estimate is not held, whatever the first
    // analysis said of it.
    for (const auto& red : id.at("redundancies"))
      if (identified.count(red.at("parameter").get<std::string>()) == 0)
        a.confounded.push_back(red.at("explanation").get<std::string>());
    for (const auto& d : id.value("ill_conditioned", nlohmann::json::array()))
      a.weak.push_back(d.at("explanation").get<std::string>());
    const nlohmann::json relin = r.value("relinearisation", nlohmann::json::object());
    if (relin.value("attempted", false)) a.relinearised = relin.value("message", std::string());
    a.underdetermined = id.value("underdetermined", false);
    a.equations = id.value("equations", std::size_t{0});
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: malformed parameter analysis ({})", where, e.what()));
  }
  return a;
}

IdentificationFile read_identification(const ResultsLayout& results, const calib::Mechanism& model,
                                       const std::string& hint) {
  const std::string file = results.identification().string();
  IdentificationFile out;
  out.report = read_json_file(results.identification(), hint);
  out.status = out.report.value("status", "");
  if (out.status != "ok") return out;
  out.start = params_from_json(model, out.report.at("start"), file);
  out.estimate = params_from_json(model, out.report.at("estimate"), file);
  if (out.report.contains("pixel_route") && out.report["pixel_route"].value("status", "") == "ok")
    out.pixel_estimate = params_from_json(model, out.report["pixel_route"].at("estimate"), file);
  // The parameter analysis is the report's (the counts and labels it shows); a file without one
  // (written by another tool, or by hand) still gives the estimate to the stages that only need it.
  if (out.report.contains("result") || out.report.contains("parameters"))
    out.parameters = parameter_account(out.report, file);
  return out;
}

// ---- validation.json ----------------------------------------------------------------------------

ValidationFile read_validation(const ResultsLayout& results, const std::string& hint) {
  const std::string file = results.report("validation").string();
  ValidationFile out;
  out.report = read_json_file(results.report("validation"), hint);
  out.status = out.report.value("status", "");
  if (!out.report.contains("held_out_points")) return out;
  const nlohmann::json& p = out.report.at("held_out_points");
  const auto rows = [&](const char* field) {
    const std::string where = fmt::format("{}: held_out_points.{}", file, field);
    if (!p.contains(field) || !p.at(field).is_array()) throw InputError(where + ": missing");
    std::vector<Eigen::Vector3d> v;
    for (std::size_t k = 0; k < p.at(field).size(); ++k)
      v.emplace_back(to_vector(numbers(p.at(field)[k], 3, fmt::format("{}[{}]", where, k))));
    return v;
  };
  const auto position = rows("position_m");
  const auto nominal = rows("nominal_error_m");
  const auto calibrated = rows("calibrated_error_m");
  if (nominal.size() != position.size() || calibrated.size() != position.size())
    throw InputError(file +
                     ": held_out_points: position_m, nominal_error_m and "
                     "calibrated_error_m differ in length");
  const nlohmann::json inside = p.value("inside_measured_region", nlohmann::json::array());
  for (std::size_t k = 0; k < position.size(); ++k) {
    HeldOutPoint h{position[k], nominal[k], calibrated[k], std::nullopt};
    if (k < inside.size() && inside[k].is_boolean())
      h.inside_measured_region = inside[k].get<bool>();
    out.points.push_back(h);
  }
  return out;
}

// ---- held_out.json ------------------------------------------------------------------------------

namespace {

HeldOutFigures figures_of(const std::vector<HeldOutPose>& poses, bool calibrated) {
  std::vector<Eigen::Vector3d> predicted, measured;
  for (const auto& p : poses) {
    measured.push_back(p.measured);
    predicted.emplace_back(p.measured + (calibrated ? p.calibrated_error : p.nominal_error));
  }
  const auto stats = calib::position_error_stats(predicted, measured);
  return {stats.n, stats.rms, stats.max};
}

nlohmann::json figures_json(const HeldOutFigures& f) {
  return {{"poses", f.poses}, {"rms_m", f.rms_m}, {"max_m", f.max_m}};
}

}  // namespace

void write_held_out(const ResultsLayout& results, const HeldOutRecord& record) {
  nlohmann::json poses = nlohmann::json::array();
  for (const auto& p : record.poses)
    poses.push_back({{"pose", p.pose},
                     {"measured_position_m", vector_json(p.measured)},
                     {"nominal_error_m", vector_json(p.nominal_error)},
                     {"calibrated_error_m", vector_json(p.calibrated_error)}});
  const nlohmann::json doc{
      {"stage", "held_out"},
      {"what",
       "held-out poses measured by the cameras: every K-th used pose left out of a second "
       "identification; errors of the model fitted without them (calibrated) and of the nominal "
       "model with its base frame fitted (nominal), against the measured board positions in "
       "camera 0's frame"},
      {"held_out_every", record.every},
      {"fit_poses", record.fit_poses},
      {"calibrated", figures_json(figures_of(record.poses, true))},
      {"nominal", figures_json(figures_of(record.poses, false))},
      {"unanswered", record.unanswered},
      {"poses", poses}};
  fs::create_directories(results.dir());
  write_json(doc, results.held_out().string());
}

HeldOutRecord read_held_out(const ResultsLayout& results, const std::string& hint) {
  const std::string file = results.held_out().string();
  const nlohmann::json doc = read_json_file(results.held_out(), hint);
  HeldOutRecord out;
  try {
    out.every = doc.at("held_out_every").get<int>();
    out.fit_poses = doc.at("fit_poses").get<std::size_t>();
    for (const auto& u : doc.at("unanswered")) out.unanswered.push_back(u.get<std::string>());
    const auto& poses = doc.at("poses");
    for (std::size_t k = 0; k < poses.size(); ++k) {
      const auto& p = poses[k];
      const auto row = [&](const char* field) {
        return to_vector(numbers(p.at(field), 3, fmt::format("{}: poses[{}].{}", file, k, field)));
      };
      out.poses.push_back({p.at("pose").get<std::string>(), row("measured_position_m"),
                           row("nominal_error_m"), row("calibrated_error_m")});
    }
    for (auto [field, figures] :
         {std::pair{"calibrated", &out.calibrated}, std::pair{"nominal", &out.nominal}}) {
      const auto& f = doc.at(field);
      *figures = {f.at("poses").get<std::size_t>(), f.at("rms_m").get<double>(),
                  f.at("max_m").get<double>()};
      if (figures->poses != out.poses.size())
        throw InputError(fmt::format("{}: {}.poses is {} but the file lists {} poses", file, field,
                                     figures->poses, out.poses.size()));
    }
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: malformed ({})", file, e.what()));
  }
  return out;
}

// ---- demo.json ----------------------------------------------------------------------------------

std::vector<std::pair<std::string, double>> read_demo_seconds(const ResultsLayout& results) {
  std::vector<std::pair<std::string, double>> out;
  const fs::path path = results.report("demo");
  if (!fs::exists(path)) return out;
  const nlohmann::json doc = read_json_file(path, "");
  if (!doc.contains("seconds")) return out;
  for (const auto& [name, seconds] : doc.at("seconds").items()) {
    if (!seconds.is_number())
      throw InputError(fmt::format("{}: seconds.{}: expected a number", path.string(), name));
    out.emplace_back(name, seconds.get<double>());
  }
  return out;
}

// ---- report.html --------------------------------------------------------------------------------

void write_report_page(const ResultsLayout& results, const std::string& html) {
  core::write_file_atomic(results.report_page(), html, core::Overwrite::kReplace);
}

// ---- truth/truth.json -------------------------------------------------------------------------

namespace {

nlohmann::json perturbation_json(const TruthPerturbation& t) {
  nlohmann::json j = {{"length_sigma_m", t.length_sigma_m}, {"angle_sigma_rad", t.angle_sigma_rad}};
  if (t.actuator_noise) j["actuator_noise"] = *t.actuator_noise;
  if (t.actuator_step) j["actuator_step"] = *t.actuator_step;
  if (!t.source.empty()) j["source"] = t.source;
  return j;
}

}  // namespace

void write_truth(const ResultsLayout& results, const calib::Mechanism& model,
                 const TruthFile& truth) {
  nlohmann::json cams = nlohmann::json::array();
  for (const auto& c : truth.cameras) {
    nlohmann::json j = vision::camera_to_json(c.model);
    j["name"] = c.name;
    j["camera_T_world"] = pose_to_json(c.camera_T_world);
    cams.push_back(j);
  }
  nlohmann::json poses = nlohmann::json::array();
  for (const auto& p : truth.poses)
    poses.push_back({{"pose", p.pose},
                     {"true_actuators", vector_json(p.true_actuators)},
                     {"world_T_board", pose_to_json(p.world_T_board)}});
  const nlohmann::json doc{
      {"note", "ground truth of a simulated session: only `validate` reads it"},
      {"world", "the robot's nominal base frame"},
      {"cameras", cams},
      {"poses", poses},
      {"nominal", params_json(model, truth.nominal)},
      {"truth", params_json(model, truth.truth)},
      {"perturbation", perturbation_json(truth.perturbation)},
      {"elastic_sag",
       {{"per_m", truth.elastic_sag},
        {"model", "the frame sinks along -z of the world by per_m * (x^2 + y^2)"}}}};
  core::write_file_atomic(results.truth(), doc.dump(2) + "\n", core::Overwrite::kRefuse);
}

TruthFile read_truth(const ResultsLayout& results, const calib::Mechanism& model) {
  const std::string file = results.truth().string();
  const nlohmann::json doc = read_json_file(results.truth(), "simulation truth");
  TruthFile out;
  try {
    out.truth = params_from_json(model, doc.at("truth"), file);
    out.nominal = params_from_json(model, doc.at("nominal"), file);
    for (const auto& c : doc.at("cameras"))
      out.cameras.push_back({c.value("name", ""), vision::camera_from_json(c, file + ": cameras"),
                             pose_from_json(c.at("camera_T_world"), file)});
    for (const auto& p : doc.at("poses"))
      out.poses.push_back({p.at("pose").get<std::string>(),
                           to_vector(p.at("true_actuators").get<std::vector<double>>()),
                           pose_from_json(p.at("world_T_board"), file)});
    if (doc.contains("perturbation")) {
      const nlohmann::json& j = doc.at("perturbation");
      TruthPerturbation& t = out.perturbation;
      t.length_sigma_m = j.value("length_sigma_m", 0.0);
      t.angle_sigma_rad = j.value("angle_sigma_rad", 0.0);
      if (j.contains("actuator_noise")) t.actuator_noise = j.at("actuator_noise").get<double>();
      if (j.contains("actuator_step")) t.actuator_step = j.at("actuator_step").get<double>();
      t.source = j.value("source", "");
    }
    if (doc.contains("elastic_sag"))
      out.elastic_sag = doc.at("elastic_sag").at("per_m").get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: malformed ({})", file, e.what()));
  }
  return out;
}

std::string measurement_refusal(const ResultsLayout& results) {
  std::error_code missing;
  if (!std::filesystem::is_regular_file(results.report("measure"), missing)) return "";
  const nlohmann::json report = read_json_file(results.report("measure"), "measure's report");
  if (report.value("status", "") != "implausible") return "";
  return report.value("message", std::string("the measurements failed the plausibility gate"));
}

}  // namespace robocal::app
