// `robocal kin`: forward/inverse kinematics, parameter Jacobians and model checks of a robot file,
// as JSON. `--set NAME=VALUE` studies a perturbed robot without editing the file.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/frame_checks.hpp"
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/plausibility.hpp"
#include "robocal/calib/robot_file.hpp"

#include <fmt/core.h>

#include <Eigen/Geometry>

#include <memory>
#include <sstream>

namespace robocal::app {
namespace {

using namespace robocal::calib;

struct KinOptions {
  std::string robot;
  std::vector<std::string> sets;
  std::string frame;
  std::string output = "-";
  std::string actuators;
  std::string seed;
  std::string position, rotation;
  std::string joint_value;
};

std::vector<double> parse_list(const std::string& text, const std::string& option) {
  std::vector<double> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    try {
      out.push_back(evaluate_expression(item));
    } catch (const std::invalid_argument& e) {
      throw UsageError(option + ": " + e.what());
    }
  }
  return out;
}

Eigen::VectorXd parse_vector(const std::string& text, std::size_t expected,
                             const std::string& option, const std::string& what) {
  const std::vector<double> v = parse_list(text, option);
  if (v.size() != expected)
    throw UsageError(option + " needs " + std::to_string(expected) + " comma-separated " + what +
                     ", got " + std::to_string(v.size()));
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

struct LoadedRobot {
  Mechanism model;
  Eigen::VectorXd params;
  int frame = -1;
};

LoadedRobot load(const KinOptions& o) {
  LoadedRobot r;
  try {
    r.model = load_robot_file(o.robot);
    r.params = r.model.nominal_parameters();
    for (const std::string& s : o.sets) apply_parameter_override(r.model, r.params, s);
  } catch (const RobotFileError& e) {
    throw InputError(e.what());
  }
  r.frame = r.model.tool;
  if (!o.frame.empty()) {
    r.frame = r.model.body_index(o.frame);
    if (r.frame < 0)
      throw InputError(o.robot + ": --frame " + o.frame + ": no body or frame of that name");
  }
  return r;
}

nlohmann::json pose_json(const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond qn(T.linear());
  const Eigen::Vector3d rv = rotation_log(T.linear());
  nlohmann::json rot = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) rot.push_back({T(i, 0), T(i, 1), T(i, 2)});
  return {{"position", {T(0, 3), T(1, 3), T(2, 3)}},
          {"rotation_matrix", rot},
          {"quaternion_wxyz", {qn.w(), qn.x(), qn.y(), qn.z()}},
          {"rotation_vector", {rv.x(), rv.y(), rv.z()}}};
}

nlohmann::json joints_json(const Mechanism& m, const std::vector<int>& bodies,
                           const Eigen::VectorXd& values) {
  nlohmann::json j = nlohmann::json::object();
  for (std::size_t i = 0; i < bodies.size(); ++i)
    j[m.bodies[bodies[i]].name] = values[static_cast<Eigen::Index>(i)];
  return j;
}

// The assembly-mode verdict of a solved state and the value of every declared invariant.
nlohmann::json mode_json(const Mechanism& m, const Eigen::VectorXd& params, const JointState& state,
                         const ModeCheck& mode) {
  nlohmann::json j = {{"verdict", to_string(mode.verdict)}, {"summary", mode.describe()}};
  if (mode.verdict == ModeVerdict::kUndeclared) return j;
  j["margin"] = mode.margin;
  j["distance_to_singularity"] = mode.distance;
  j["ambiguity_band"] = m.assembly_mode.ambiguity;
  if (!mode.invariant.empty()) j["invariant"] = mode.invariant;
  std::vector<Eigen::Isometry3d> poses;
  body_poses(m, params, state, poses);
  nlohmann::json values = nlohmann::json::object();
  for (const ModeInvariant& inv : m.assembly_mode.invariants)
    values[inv.name] = {{"value", invariant_value(inv, poses, state, m)},
                        {"intended_sign", inv.sign > 0 ? "positive" : "negative"}};
  j["invariants"] = values;
  return j;
}

nlohmann::json header(const LoadedRobot& r) {
  return {{"robot", r.model.name},
          {"file", r.model.source},
          {"frame", r.model.bodies[r.frame].name},
          {"pose_convention",
           "pose maps frame coordinates to world: x_world = R x_frame + p; "
           "lengths m, angles rad"}};
}

int run_fk(const KinOptions& o, bool jacobian) {
  const LoadedRobot r = load(o);
  const Mechanism& m = r.model;
  const Eigen::VectorXd q =
      parse_vector(o.actuators, m.actuated.size(), "--actuators", "actuator readings");
  ClosureOptions copts;
  copts.diagnose = true;
  const ForwardResult fk = forward_kinematics(m, r.params, q, r.frame, Eigen::VectorXd(), copts);
  nlohmann::json doc = header(r);
  doc["status"] = to_string(fk.closure.status);
  doc["closure_residual"] = fk.closure.residual;
  doc["iterations"] = fk.closure.iterations;
  doc["constraint_rank"] = fk.closure.rank;
  doc["actuator_readings"] = joints_json(m, m.actuated, q);
  if (fk.closure.passive.size() == static_cast<Eigen::Index>(m.passive.size()))
    doc["passive_joints"] = joints_json(m, m.passive, fk.closure.passive);
  const bool closed =
      fk.closure.status == SolveStatus::kConverged || fk.closure.status == SolveStatus::kSingular;
  if (closed || fk.closure.status == SolveStatus::kOtherMode) {
    doc["assembly_mode"] = mode_json(m, r.params, fk.state, fk.closure.mode);
    doc["seed"] = fk.closure.seed_used;
  }
  // An answer on another assembly mode is refused: no pose, exit 1, the reason. A serial chain's
  // forward answer is unique (no loop to re-seed): reported with its verdict.
  const bool serial = m.passive.empty();
  // Readings the robot cannot have (outside its joint limits) get no pose, whatever the closure
  // solver finds for them.
  const auto limits_problem = readings_problem(m, r.params, q);
  if (limits_problem) doc["limits"] = *limits_problem;
  const bool ok = closed && !limits_problem && (fk.closure.mode.acceptable() || serial);
  if (ok && !fk.closure.mode.acceptable())
    doc["note"] = "these joint values put the arm in " + fk.closure.mode.describe();
  if (!ok)
    doc["reason"] = limits_problem ? *limits_problem
                    : fk.closure.status == SolveStatus::kOtherMode || !fk.closure.mode.acceptable()
                        ? "the loops close only on " + fk.closure.mode.describe() +
                              " (every seed tried); the robot cannot be in its intended mode at "
                              "these readings"
                        : std::string("the loops do not close at these readings (") +
                              to_string(fk.closure.status) + ")";
  if (ok) doc["pose"] = pose_json(fk.pose);
  // Near a singularity the loops close on more than one assembly mode within the ambiguity
  // band: the pose may be another mode's (centimetres off), so it is no answer to rely on.
  const bool ambiguous = ok && !serial && fk.closure.mode.verdict == ModeVerdict::kAmbiguous;
  if (ambiguous) {
    doc["closure_status"] = doc["status"];
    doc["status"] = "ambiguous";
    doc["reason"] = "these readings are within the assembly-mode ambiguity band (" +
                    fk.closure.mode.describe() +
                    "): the loops close on more than one mode here, so the pose may be another "
                    "mode's; move away from the singularity";
    fmt::print(stderr, "kin fk: assembly mode ambiguous: {}\n", doc["reason"].get<std::string>());
  }
  if (ok && jacobian) {
    const FrameJacobians J = frame_jacobians(m, r.params, fk.state, q, r.frame);
    doc["jacobian_convention"] =
        "rows: d(position)/dx (world), d(rotation)/dx as world small-angle vector w with "
        "R(x+dx) = Exp(w dx) R(x); through the closures (implicit-function theorem)";
    nlohmann::json params = nlohmann::json::array();
    for (std::size_t k = 0; k < m.parameters.size(); ++k) {
      const auto c = J.parameters.col(static_cast<Eigen::Index>(k));
      params.push_back({{"name", m.parameters[k].name},
                        {"free", m.parameters[k].free},
                        {"d_position", {c[0], c[1], c[2]}},
                        {"d_rotation", {c[3], c[4], c[5]}}});
    }
    doc["parameters"] = params;
    nlohmann::json acts = nlohmann::json::array();
    for (std::size_t i = 0; i < m.actuated.size(); ++i) {
      const auto c = J.actuators.col(static_cast<Eigen::Index>(i));
      acts.push_back({{"name", m.bodies[m.actuated[i]].name},
                      {"d_position", {c[0], c[1], c[2]}},
                      {"d_rotation", {c[3], c[4], c[5]}}});
    }
    doc["actuators"] = acts;
  }
  write_json(doc, o.output);
  return ok && !ambiguous ? int{kExitOk} : int{kExitFailure};
}

int run_ik(const KinOptions& o) {
  const LoadedRobot r = load(o);
  const Mechanism& m = r.model;
  if (!o.frame.empty() && r.frame != m.task.frame)
    throw InputError(o.robot + ": --frame " + o.frame +
                     ": inverse kinematics uses the task frame '" + m.bodies[m.task.frame].name +
                     "' of the robot file");
  TaskTarget target;
  switch (m.task.type) {
    case TaskType::kJoint:
      if (o.joint_value.empty())
        throw InputError(o.robot + ": task is the value of joint '" + m.bodies[m.task.joint].name +
                         "': give --joint-value");
      target.joint_value = parse_vector(o.joint_value, 1, "--joint-value", "value")[0];
      break;
    case TaskType::kPosition:
    case TaskType::kPose:
      if (o.position.empty())
        throw InputError(o.robot + ": task is the " +
                         (m.task.type == TaskType::kPose ? "pose" : "position") + " of frame '" +
                         m.bodies[m.task.frame].name + "': give --position x,y,z");
      target.pose.translation() = parse_vector(o.position, 3, "--position", "coordinates");
      if (!o.rotation.empty())
        target.pose.linear() =
            rotation_exp(parse_vector(o.rotation, 3, "--rotation-vector", "components"));
      break;
  }
  IkSeed seed;
  if (!o.seed.empty())
    seed.actuator_q = parse_vector(o.seed, m.actuated.size(), "--seed", "actuator joint values");
  const IkResult ik = solve_ik(m, r.params, target, seed);
  nlohmann::json doc = header(r);
  doc["frame"] = m.bodies[m.task.frame].name;
  doc["task"] = m.task.type == TaskType::kJoint  ? "joint"
                : m.task.type == TaskType::kPose ? "pose"
                                                 : "position";
  doc["status"] = to_string(ik.status);
  doc["residual"] = ik.residual;
  doc["iterations"] = ik.iterations;
  const bool ok = ik.ok() && ik.mode.acceptable();
  if (ik.actuator_q.size() == static_cast<Eigen::Index>(m.actuated.size())) {
    const JointState state = make_joint_state(m, r.params, ik.actuator_readings, ik.passive);
    if (ik.ok() || ik.status == SolveStatus::kOtherMode)
      doc["assembly_mode"] = mode_json(m, r.params, state, ik.mode);
    if (ok) {
      doc["actuator_readings"] = joints_json(m, m.actuated, ik.actuator_readings);
      doc["actuator_joint_values"] = joints_json(m, m.actuated, ik.actuator_q);
      doc["passive_joints"] = joints_json(m, m.passive, ik.passive);
    }
  }
  if (!ok)
    doc["reason"] =
        ik.status == SolveStatus::kOtherMode
            ? "the target is reached only on " + ik.mode.describe() + " (every seed tried)"
            : std::string("no solution reaches the target (") + to_string(ik.status) + ")";
  write_json(doc, o.output);
  return ok ? int{kExitOk} : int{kExitFailure};
}

const char* type_name(JointType t) {
  switch (t) {
    case JointType::kRevolute:
      return "revolute";
    case JointType::kPrismatic:
      return "prismatic";
    case JointType::kFixed:
      return "fixed";
  }
  return "?";
}
const char* role_name(JointRole r) {
  switch (r) {
    case JointRole::kActuated:
      return "actuated";
    case JointRole::kPassive:
      return "passive";
    case JointRole::kCut:
      return "cut";
    case JointRole::kAuxiliary:
      return "auxiliary";
  }
  return "?";
}
const char* closure_name(ClosureType t) {
  switch (t) {
    case ClosureType::kPose:
      return "pose";
    case ClosureType::kPosition:
      return "position";
    case ClosureType::kPositionAxis:
      return "position_axis";
    case ClosureType::kDistance:
      return "distance";
  }
  return "?";
}

int run_check(const KinOptions& o) {
  const LoadedRobot r = load(o);
  const Mechanism& m = r.model;
  nlohmann::json doc = header(r);
  nlohmann::json bodies = nlohmann::json::array();
  for (const Body& b : m.bodies)
    bodies.push_back({{"name", b.name},
                      {"parent", b.parent >= 0 ? m.bodies[b.parent].name : "world"},
                      {"convention", b.convention},
                      {"joint", type_name(b.joint)},
                      {"role", role_name(b.role)},
                      {"collision_shapes", b.collision.size()}});
  doc["bodies"] = bodies;
  nlohmann::json closures = nlohmann::json::array();
  for (const Closure& c : m.closures)
    closures.push_back({{"name", c.name},
                        {"type", closure_name(c.type)},
                        {"a", m.bodies[c.body_a].name},
                        {"b", m.bodies[c.body_b].name},
                        {"rows", closure_rows(c.type)}});
  doc["closures"] = closures;
  std::vector<std::string> act, pas;
  for (int b : m.actuated) act.push_back(m.bodies[b].name);
  for (int b : m.passive) pas.push_back(m.bodies[b].name);
  doc["actuated_joints"] = act;
  doc["free_joints"] = pas;
  doc["constraint_rows"] = m.constraint_rows();
  int free_params = 0;
  for (const Parameter& p : m.parameters) free_params += p.free ? 1 : 0;
  doc["parameter_count"] = m.parameters.size();
  doc["free_parameter_count"] = free_params;
  // Constraint rank at the home configuration (actuators at their home values).
  Eigen::VectorXd home_q(static_cast<Eigen::Index>(m.actuated.size()));
  for (std::size_t i = 0; i < m.actuated.size(); ++i)
    home_q[static_cast<Eigen::Index>(i)] = m.bodies[m.actuated[i]].home;
  ClosureOptions copts;
  copts.diagnose = true;
  const ClosureResult c =
      solve_closure(m, r.params, readings_from_joint_values(m, r.params, home_q), {}, copts);
  doc["home_closure"] = {{"status", to_string(c.status)}, {"residual", c.residual},
                         {"constraint_rank", c.rank},     {"unknowns", c.unknowns},
                         {"equations", c.equations},      {"sigma_min", c.sigma_min},
                         {"sigma_max", c.sigma_max}};
  if (c.passive.size() == static_cast<Eigen::Index>(m.passive.size()))
    doc["home_closure"]["assembly_mode"] = mode_json(
        m, r.params,
        make_joint_state(m, r.params, readings_from_joint_values(m, r.params, home_q), c.passive),
        c.mode);
  nlohmann::json invariants = nlohmann::json::array();
  for (const ModeInvariant& inv : m.assembly_mode.invariants) {
    std::vector<std::string> names;
    for (int b : inv.bodies) names.push_back(m.bodies[static_cast<std::size_t>(b)].name);
    invariants.push_back({{"name", inv.name},
                          {"bodies", names},
                          {"intended_sign", inv.sign > 0 ? "positive" : "negative"}});
  }
  doc["assembly_mode"] = {{"declared", !m.assembly_mode.invariants.empty()},
                          {"ambiguity_band", m.assembly_mode.ambiguity},
                          {"invariants", invariants}};
  std::vector<std::string> notes;
  if (c.rank >= 0 && c.rank < c.unknowns)
    notes.push_back("constraint rank " + std::to_string(c.rank) + " < " +
                    std::to_string(c.unknowns) +
                    " free joints at home: idle mobility or singular home pose");
  if (c.equations > c.rank && c.rank >= 0)
    notes.push_back(std::to_string(c.equations - c.rank) +
                    " constraint row(s) redundant at home (e.g. a planar loop closed in 3-D)");
  // Issue 22: frames at or near gimbal lock (stderr too: a warning a user must see).
  for (const std::string& w : gimbal_lock_warnings(m)) {
    notes.push_back("warning: " + w);
    fmt::print(stderr, "warning: {}\n", w);
  }
  doc["notes"] = notes;
  write_json(doc, o.output);
  return (c.ok() || c.status == SolveStatus::kSingular) && c.mode.acceptable() ? int{kExitOk}
                                                                               : int{kExitFailure};
}

void add_common(CLI::App* sub, KinOptions& o) {
  sub->add_option("robot", o.robot, "Robot description file (YAML, see testdata/robots/README.md)")
      ->required();
  sub->add_option("--set", o.sets,
                  "Override a parameter: NAME=VALUE (e.g. body26.d1=0.901, rod_a.length=0.27); "
                  "repeatable")
      ->allow_extra_args(false);
  sub->add_option("-o,--output", o.output, "Write JSON here (default: stdout)");
}

}  // namespace

CommandSpec kin_command() {
  return {"kin",
          "Kinematics of a robot file: fk, ik, jacobian, check (JSON output). Every answer "
          "carries its assembly-mode verdict; one that only another mode gives is refused "
          "(exit 1, with the reason)",
          [](CLI::App& cmd) -> CommandAction {
            auto o = std::make_shared<KinOptions>();
            cmd.require_subcommand(1);
            CLI::App* fk = cmd.add_subcommand(
                "fk", "Forward kinematics: actuator readings -> frame pose (closure solved)");
            add_common(fk, *o);
            fk->add_option("--actuators", o->actuators,
                           "Actuator readings in file order, comma separated (encoder units)")
                ->required();
            fk->add_option("--frame", o->frame, "Frame (body) name; default: the tool");
            CLI::App* jac = cmd.add_subcommand(
                "jacobian", "Pose of a frame and its Jacobian w.r.t. every parameter and actuator");
            add_common(jac, *o);
            jac->add_option("--actuators", o->actuators, "Actuator readings, comma separated")
                ->required();
            jac->add_option("--frame", o->frame, "Frame (body) name; default: the tool");
            CLI::App* ik =
                cmd.add_subcommand("ik", "Inverse kinematics: task target -> actuator readings");
            add_common(ik, *o);
            ik->add_option("--position", o->position, "Target position x,y,z (m)");
            ik->add_option("--rotation-vector", o->rotation,
                           "Target orientation as a world rotation vector rx,ry,rz (rad); pose "
                           "tasks only; default identity");
            ik->add_option("--joint-value", o->joint_value, "Target joint value (joint tasks)");
            ik->add_option("--seed", o->seed, "Start from these actuator joint values");
            ik->add_option("--frame", o->frame, "Must be the robot file's task frame");
            CLI::App* check = cmd.add_subcommand(
                "check",
                "Load a robot file and report tree, closures, free joints, rank, parameters");
            add_common(check, *o);
            return [o, fk, jac, ik, check]() {
              if (fk->parsed()) return run_fk(*o, false);
              if (jac->parsed()) return run_fk(*o, true);
              if (ik->parsed()) return run_ik(*o);
              if (check->parsed()) return run_check(*o);
              return int{kExitUsage};
            };
          }};
}

}  // namespace robocal::app
