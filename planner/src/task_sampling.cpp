// Task-space candidates facing the cameras (see task_sampling.hpp).
#include "robocal/planner/task_sampling.hpp"

#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/vision/camera_model.hpp"

#include <algorithm>
#include <cmath>

namespace robocal::planner {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Incidence kept in reserve below the cell's maximum (the nominal robot and intrinsics are all
// the plan knows; a pose right at the limit may fail on the real cell).
constexpr double kIncidenceReserve = 0.1;  // rad
// Joint samples drawn to find one on the intended mode whose target centre the cameras can see,
// per candidate.
constexpr int kSeedTries = 256;

}  // namespace

bool task_space_sampling_applies(const FeasibilityChecker& checker) {
  const calib::Mechanism& model = checker.reach().model();
  // Six actuators at least: a robot with fewer (the 4-DOF wire robot's branch) cannot turn the
  // target to an arbitrary orientation, and its least-squares IK answers another pose.
  return model.task.type == calib::TaskType::kPose && model.task.frame == checker.frame() &&
         model.actuated.size() >= 6 && !checker.cell().required_cameras().empty();
}

std::vector<Candidate> sample_facing_cameras(const FeasibilityChecker& checker, std::size_t count,
                                             std::mt19937& rng, FeasibilityCounts* counts) {
  const ReachChecker& reach = checker.reach();
  const calib::Mechanism& model = reach.model();
  const Eigen::VectorXd& params = reach.params();
  const Cell& cell = checker.cell();
  Eigen::VectorXd lo, hi;
  reach.reading_limits(lo, hi);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector3d> eyes;
  std::vector<const CellCamera*> cams;
  for (const int ci : cell.required_cameras()) {
    cams.push_back(&cell.cameras.at(static_cast<std::size_t>(ci)));
    eyes.emplace_back(cams.back()->world_T_camera.translation());
  }
  Eigen::Vector3d eye_mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& e : eyes) eye_mean += e / static_cast<double>(eyes.size());
  // The board's centre in the board frame.
  const std::vector<Eigen::Vector3d> outline = board_outline(cell.target.board);
  Eigen::Vector3d board_mid = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : outline) board_mid += p / 4.0;
  const Eigen::Isometry3d board_T_frame = cell.target.frame_T_board.inverse();
  const double short_side =
      std::min((outline[1] - outline[0]).norm(), (outline[3] - outline[0]).norm());
  // Whether a target centred at `centre` and facing a camera squarely could be seen whole by
  // every required camera: the centre inside the image by half the target's image size (plus
  // the border), the target's image at least the minimum size.
  auto centre_in_view = [&](const Eigen::Vector3d& centre) {
    for (const CellCamera* cam : cams) {
      const Eigen::Vector3d pc = cam->world_T_camera.inverse() * centre;
      if (pc.z() <= 0) return false;
      const double fx = cam->model.params.empty() ? 0.0 : cam->model.params[0];
      const double size = fx * short_side / pc.norm();
      if (size < cell.visibility.min_image_size) return false;
      const auto px = vision::project(cam->model, pc);
      if (!px || !vision::in_image(cam->model, *px, cell.margins.image_border + 0.5 * size))
        return false;
    }
    return true;
  };

  calib::IkOptions ik;
  ik.respect_limits = true;
  ik.enforce_mode = true;
  ik.multi_start = 8;
  std::vector<Candidate> out;
  out.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    // A joint sample on the intended mode: the position and the IK seed.
    Eigen::VectorXd x(lo.size());
    ReachResult seed;
    for (int t = 0; t < kSeedTries; ++t) {
      for (Eigen::Index k = 0; k < lo.size(); ++k) x(k) = lo(k) + u(rng) * (hi(k) - lo(k));
      seed = reach.reach_check(x);
      if (seed.ok() && centre_in_view(seed.body_poses[static_cast<std::size_t>(checker.frame())] *
                                      cell.target.frame_T_board * board_mid))
        break;
    }
    Candidate c;
    if (!seed.ok()) {  // the last draw's verdict stands for the candidate (a seed whose target
                       // the cameras cannot see goes on: the visibility test will say why)
      c.readings = x;
      c.rejection = rejection_of(seed.verdict);
      c.detail = seed.detail;
    } else {
      const Eigen::Isometry3d world_T_board0 =
          seed.body_poses[static_cast<std::size_t>(checker.frame())] * cell.target.frame_T_board;
      const Eigen::Vector3d centre = world_T_board0 * board_mid;
      const Eigen::Vector3d n0 = (eye_mean - centre).normalized();
      // Tilt that keeps every required camera within the maximum incidence.
      double spread = 0.0;
      for (const Eigen::Vector3d& e : eyes)
        spread =
            std::max(spread, std::acos(std::clamp(n0.dot((e - centre).normalized()), -1.0, 1.0)));
      const double max_tilt =
          std::max(0.0, cell.visibility.max_incidence - spread - kIncidenceReserve);
      const double a = 2 * kPi * u(rng);
      const Eigen::Vector3d e1 = n0.unitOrthogonal(), e2 = n0.cross(e1);
      const Eigen::Vector3d axis = std::cos(a) * e1 + std::sin(a) * e2;
      const Eigen::Vector3d n = Eigen::AngleAxisd(max_tilt * u(rng), axis) * n0;
      // Board z = -n (the printed face looks along -z), random turn about it.
      Eigen::Matrix3d R =
          Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), -n).toRotationMatrix();
      R = R * Eigen::AngleAxisd(2 * kPi * u(rng), Eigen::Vector3d::UnitZ()).toRotationMatrix();
      Eigen::Isometry3d world_T_board = Eigen::Isometry3d::Identity();
      world_T_board.linear() = R;
      world_T_board.translation() = centre - R * board_mid;
      calib::TaskTarget target;
      target.pose = world_T_board * board_T_frame;
      calib::IkSeed ik_seed;
      ik_seed.actuator_q.resize(static_cast<Eigen::Index>(model.actuated.size()));
      for (std::size_t k = 0; k < model.actuated.size(); ++k)
        ik_seed.actuator_q(static_cast<Eigen::Index>(k)) = seed.state.q(model.actuated[k]);
      ik_seed.passive = seed.passive;
      const calib::IkResult r = calib::solve_ik(model, params, target, ik_seed, ik);
      if (r.ok()) {
        c = checker.evaluate(reach.nearest_turn_to_home(r.actuator_readings));
      } else {
        c.readings = x;
        c.rejection = r.status == calib::SolveStatus::kOtherMode ? Rejection::kModeChange
                                                                 : Rejection::kNoAssembly;
        c.detail = std::string("no inverse kinematics for the board turned to the cameras (") +
                   calib::to_string(r.status) + ")";
      }
    }
    if (counts != nullptr) counts->add(c);
    out.push_back(std::move(c));
  }
  return out;
}

}  // namespace robocal::planner
