// `robocal plan`: measurement poses for a robot in a cell (front end of the planner library:
// read the files, run planner::plan_measurements, write the plan and the preview, report).
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/staging.hpp"
#include "robocal/planner/camera_placement.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/plan.hpp"
#include "robocal/planner/plan_output.hpp"
#include "robocal/planner/task_sampling.hpp"
#include "session/session_robot.hpp"

#include <fmt/core.h>

#include <filesystem>
#include <stdexcept>

namespace robocal::app {
namespace {

namespace fs = std::filesystem;
using namespace robocal::planner;

struct PlanCommandOptions {
  std::string robot;
  std::string cell;
  std::string out = "plan.yaml";
  std::string svg;
  std::string measured;
  std::string index = "O5";
  std::size_t count = 40;
  std::size_t pool = 5000;
  unsigned seed = 1;
  double max_condition = 1e4;
  double target_um = 0.0;
  bool json = false;
  bool suggest_cameras = false;
  int max_cameras = 2;
  bool no_order = false;
};

const char* status_word(PlanStatus s) {
  switch (s) {
    case PlanStatus::kOk:
      return "ok";
    case PlanStatus::kNotAccepted:
      return "not accepted";
    case PlanStatus::kInfeasible:
      return "infeasible";
    case PlanStatus::kBadCell:
      return "bad cell";
  }
  return "?";
}

// The planner refuses a robot it cannot plan for (one that cannot assemble where it must, no
// parameter identifiable from its reachable poses) with std::invalid_argument: a fault of the
// robot file given, named with it (exit 3), not an internal error.
template <typename PlannerCall>
auto for_robot(const calib::Mechanism& model, const PlannerCall& call) {
  try {
    return call();
  } catch (const std::invalid_argument& e) {
    const std::string why = e.what();
    throw InputError(why.rfind(model.source, 0) == 0 ? why : model.source + ": " + why);
  }
}

int run_plan(const PlanCommandOptions& o) {
  const Cell cell = load_cell_file(o.cell);  // bad input: core::InputError, exit 3
  std::string robot = o.robot.empty() ? cell.robot_file : o.robot;
  if (robot.empty())
    throw InputError("no robot: give --robot NAME|FILE or name one in the cell file ('robot:')");
  calib::Mechanism model;
  try {
    model = calib::load_robot_file(resolve_robot(robot));
  } catch (const calib::RobotFileError& e) {
    throw InputError(e.what());
  }
  const Eigen::VectorXd params = model.nominal_parameters();

  nlohmann::json report;
  report["robot"] = model.name;
  report["cell"] = cell.source;
  if (o.suggest_cameras) {
    PlacementOptions placement;
    placement.max_cameras = o.max_cameras;
    const CameraPlacement p =
        for_robot(model, [&] { return propose_cameras(model, params, cell, placement); });
    // Camera i looks at its station's point (an array), or the pair's.
    const auto look_at_of = [&p](std::size_t i) {
      return p.cameras_per_station > 0
                 ? p.station_look_at.at(i / static_cast<std::size_t>(p.cameras_per_station))
                 : p.look_at;
    };
    nlohmann::json cams = nlohmann::json::array();
    for (std::size_t i = 0; i < p.world_T_camera.size(); ++i) {
      const Eigen::Vector3d pos = p.world_T_camera[i].translation();
      const Eigen::Vector3d at = look_at_of(i);
      cams.push_back(
          {{"position", {pos.x(), pos.y(), pos.z()}}, {"look_at", {at.x(), at.y(), at.z()}}});
    }
    report["camera_suggestion"] = {
        {"cameras", cams},        {"distance_m", p.distance},     {"baseline_m", p.baseline},
        {"coverage", p.coverage}, {"min_cameras", p.min_cameras}, {"summary", p.summary}};
    if (!o.json) {
      fmt::print("camera suggestion: {}\n", p.summary);
      for (std::size_t i = 0; i < p.world_T_camera.size(); ++i) {
        const Eigen::Vector3d pos = p.world_T_camera[i].translation();
        const Eigen::Vector3d at = look_at_of(i);
        fmt::print(
            "  - pose: {{position: [{:.3f}, {:.3f}, {:.3f}], look_at: [{:.3f}, {:.3f}, {:.3f}]}}\n",
            pos.x(), pos.y(), pos.z(), at.x(), at.y(), at.z());
      }
      if (p.min_cameras > 0)
        fmt::print("  (an array: add `visibility: {{min_cameras: {}}}` to the cell file)\n",
                   p.min_cameras);
    }
  }

  PlanOptions po;
  po.pool = o.pool;
  po.seed = o.seed;
  po.order = !o.no_order;
  po.selection.count = o.count;
  // A robot whose own joints turn its target with fewer than six actuators (the wire robot's
  // platform): candidates with the target turned towards the cameras, as the demos plan it; in
  // joint space its target faces them at a few per cent of the samples.
  po.task_space = planner::target_turned_by_joints(model, model.task.frame);
  po.selection.max_condition = o.max_condition;
  po.selection.target_accuracy = o.target_um * 1e-6;
  if (!parse_index(o.index, &po.selection.index))
    throw UsageError("--index must be O1, O2, O3, O4 or O5 (got '" + o.index + "')");
  if (!o.measured.empty()) po.measured = read_plan_actuators(o.measured);
  po.progress = [&](const std::string& line) {
    if (!o.json) fmt::print(stderr, "plan: {}\n", line);
  };
  const PlanResult plan =
      for_robot(model, [&] { return plan_measurements(model, params, cell, po); });
  report["status"] = status_word(plan.status);
  report["message"] = plan.message;
  report["feasibility"] = plan.counts.summary();
  if (plan.status == PlanStatus::kBadCell) throw InputError(plan.message);
  if (plan.poses.empty()) {
    // Nothing feasible: say which constraint removed how many; no plan written.
    if (o.json) {
      write_json(report, "-");
    } else {
      fmt::print(stderr, "plan: no plan written: {}\n", plan.message);
    }
    return kExitFailure;
  }
  // A plan it rejects is never written (an existing file at --out stays as it was); an accepted
  // one is written with its preview, both or neither (core/staging.hpp).
  const bool accepted = plan.status == PlanStatus::kOk;
  if (accepted) {
    core::StagedFiles files;
    files.add(o.out, plan_to_yaml(model, cell, plan, po));
    if (!o.svg.empty()) files.add(o.svg, plan_to_svg(cell, plan));
    files.commit();
    report["plan_file"] = o.out;
    if (!o.svg.empty()) report["preview"] = o.svg;
  }
  report["poses"] = plan.poses.size();
  report["condition_number"] = plan.selection.values.condition_number;
  report["accepted"] = plan.selection.accepted;
  report["predicted_position_rms_um"] = plan.selection.predicted_rms * 1e6;
  report["predicted_position_max_um"] = plan.selection.predicted_max * 1e6;
  report["tour_length"] = plan.tour.length;
  report["warnings"] = plan.warnings;
  if (o.json) {
    write_json(report, "-");
  } else {
    fmt::print("{}\n", plan.counts.summary());
    fmt::print("{}\n", plan.selection.message);
    fmt::print(
        "motion order: {} poses, actuator-space path {:.3f} (nearest neighbour alone {:.3f}), "
        "{} motions checked for collision\n",
        plan.poses.size(), plan.tour.length, plan.tour.nearest_neighbour_length,
        plan.tour.segments_checked);
    for (const std::string& w : plan.warnings) fmt::print("warning: {}\n", w);
    if (accepted)
      fmt::print("plan written to {}{}\n", o.out, o.svg.empty() ? "" : ", preview to " + o.svg);
    else
      fmt::print("the plan is NOT accepted: {}\nno plan written ({} is as it was)\n", plan.message,
                 o.out);
  }
  return plan.status == PlanStatus::kOk ? kExitOk : kExitFailure;
}

}  // namespace

CommandSpec plan_command() {
  return {
      "plan",
      "Plan measurement poses: reachable, collision-free, seen by the cameras, most informative",
      [](CLI::App& cmd) -> CommandAction {
        auto o = std::make_shared<PlanCommandOptions>();
        cmd.footer(
            "Plans where to move the robot to calibrate it. Candidate poses are sampled in\n"
            "joint space; a candidate is kept when the robot reaches it on its intended\n"
            "assembly mode (limits with margin, ball-joint cones, away from singularities),\n"
            "stays inside the cell's safe workspace, collides with nothing (FCL, with\n"
            "clearance) and every required camera sees the whole target. From those, N poses\n"
            "are chosen to make the identification as well-conditioned as possible (index\n"
            "O5 by default, the best on the Delta bench; greedy + exchange), checked by a\n"
            "condition-number test (default 1e4),\n"
            "and ordered into a short tour whose every motion is checked for collision.\n"
            "The cell file (cameras, obstacles, workspace, margins, target) is described in\n"
            "planner/README.md; examples in testdata/cells/.\n"
            "Exit codes: 0 plan written and accepted; 1 no acceptable plan, nothing written\n"
            "(the summary says which constraint removed how many candidates, or why the plan\n"
            "is not accepted); 3 bad cell/robot file (nothing written).\n"
            "Example: robocal plan --cell testdata/cells/delta_two_cameras.yaml --out plan.yaml "
            "--svg plan.svg");
        cmd.add_option("--cell", o->cell, "Cell file (YAML)")->required();
        cmd.add_option("--robot", o->robot,
                       "Robot file or library name (default: the cell's 'robot:')");
        cmd.add_option("--out", o->out, "Plan file to write (YAML)")->capture_default_str();
        cmd.add_option("--svg", o->svg, "Also write an SVG preview (top and side view)");
        cmd.add_option("--count", o->count, "Poses to plan")
            ->capture_default_str()
            ->check(CLI::Range(1, 10000));
        cmd.add_option("--pool", o->pool,
                       "Candidate poses sampled in joint space (a robot with fewer than six "
                       "actuators whose joints turn its target: each turned towards the cameras)")
            ->capture_default_str()
            ->check(CLI::Range(10, 10000000));
        cmd.add_option("--index", o->index,
                       "Observability index: O1 (D-optimal), O2 (1/condition), O3 (smallest "
                       "singular value), O4 (noise amplification), O5")
            ->capture_default_str();
        cmd.add_option("--max-condition", o->max_condition, "Acceptance: largest condition number")
            ->capture_default_str();
        cmd.add_option(
            "--target-accuracy", o->target_um,
            "Stop adding poses once the predicted position error (RMS, um) reaches this");
        cmd.add_option("--measured", o->measured,
                       "Sequential mode: a plan file whose poses are already measured; the new "
                       "plan proposes the next best poses");
        cmd.add_option("--seed", o->seed, "Sampling seed")->capture_default_str();
        cmd.add_flag("--suggest-cameras", o->suggest_cameras,
                     "Also propose camera poses that see the working volume (from the first "
                     "camera's intrinsics)");
        cmd.add_option("--max-cameras", o->max_cameras,
                       "With --suggest-cameras: up to this many cameras; from 4, an array of "
                       "pairs where one pair sees under half the reachable poses")
            ->capture_default_str()
            ->check(CLI::Range(2, 16));
        cmd.add_flag("--no-order", o->no_order, "Skip the motion order (tour)");
        cmd.add_flag("--json", o->json, "Print the summary as JSON");
        return [o] { return run_plan(*o); };
      }};
}

}  // namespace robocal::app
