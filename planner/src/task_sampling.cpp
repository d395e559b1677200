// Task-space candidates facing the cameras (see task_sampling.hpp).
#include "robocal/planner/task_sampling.hpp"

#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/vision/camera_model.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

namespace robocal::planner {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Incidence kept in reserve below the cell's maximum (the nominal robot and intrinsics are all
// the plan knows; a pose right at the limit may fail on the real cell).
constexpr double kIncidenceReserve = 0.1;  // rad
// Joint samples drawn to find one on the intended mode whose target centre the cameras can see,
// per candidate.
constexpr int kSeedTries = 256;
// Aiming a robot with fewer than six actuators (aim_face): Gauss-Newton steps at most, and the
// pull back towards the joint sample, relative to turning the face (in actuator ranges against
// unit vectors): small, so the face turns first, but enough to keep the sample's position where
// the face can be turned either way.
constexpr int kAimSteps = 15;
constexpr double kAimDamping = 0.05;
constexpr double kAimStepLimit = 0.2;    // of each actuator's range, per step
constexpr double kAimDifference = 1e-6;  // of each actuator's range: the Jacobian's step

// The target's printed face direction (the board's -z) in the world, from a reach answer.
Eigen::Vector3d face_of(const ReachResult& r, int frame, const Eigen::Matrix3d& frame_R_board) {
  return -(r.body_poses[static_cast<std::size_t>(frame)].linear() * frame_R_board).col(2);
}

// Readings near `x0` (a reachable joint sample, answer `r0`) that turn the target's face towards
// `face` (unit) as far as the robot can: damped Gauss-Newton on the face direction, in actuator
// units scaled by each actuator's range, pulled back towards x0 (minimise |f(x) - face|^2 +
// d^2 |x - x0|^2, d = kAimDamping), inside the limits. A robot with fewer than six actuators
// cannot put its target at an arbitrary pose, but where it has the joints to turn it (the wire
// robot's platform pitch and yaw), it can face it towards the cameras. Every step is solved by
// the reach test on the intended mode; nullopt where a step leaves it.
std::optional<Eigen::VectorXd> aim_face(const ReachChecker& reach, int frame,
                                        const Eigen::Matrix3d& frame_R_board,
                                        const Eigen::VectorXd& x0, const ReachResult& r0,
                                        const Eigen::Vector3d& face, const Eigen::VectorXd& lo,
                                        const Eigen::VectorXd& hi) {
  const Eigen::Index n = x0.size();
  const Eigen::VectorXd range = (hi - lo).cwiseMax(1e-12);
  Eigen::VectorXd x = x0;
  ReachResult r = r0;
  for (int step = 0; step < kAimSteps; ++step) {
    const Eigen::Vector3d f = face_of(r, frame, frame_R_board);
    const Eigen::Vector3d miss = f - face;
    if (miss.norm() < 1e-4) break;
    // The face's derivative per actuator range (forward difference, backward at the upper limit).
    Eigen::Matrix<double, 3, Eigen::Dynamic> J(3, n);
    for (Eigen::Index k = 0; k < n; ++k) {
      Eigen::VectorXd xk = x;
      const double h = (x(k) + kAimDifference * range(k) <= hi(k) ? 1.0 : -1.0) * kAimDifference;
      xk(k) += h * range(k);
      const ReachResult rk = reach.reach_check(xk, r.passive);
      if (!rk.ok()) return std::nullopt;
      J.col(k) = (face_of(rk, frame, frame_R_board) - f) / h;
    }
    const Eigen::VectorXd away = (x - x0).cwiseQuotient(range);
    const Eigen::MatrixXd A =
        J.transpose() * J + kAimDamping * kAimDamping * Eigen::MatrixXd::Identity(n, n);
    Eigen::VectorXd du = A.ldlt().solve(-(J.transpose() * miss + kAimDamping * kAimDamping * away));
    const double longest = du.cwiseAbs().maxCoeff();
    if (longest > kAimStepLimit) du *= kAimStepLimit / longest;
    const Eigen::VectorXd next = (x + du.cwiseProduct(range)).cwiseMax(lo).cwiseMin(hi);
    if ((next - x).cwiseQuotient(range).cwiseAbs().maxCoeff() < 1e-7) break;
    ReachResult rn = reach.reach_check(next, r.passive);
    if (!rn.ok()) return std::nullopt;
    x = next;
    r = std::move(rn);
  }
  return x;
}

}  // namespace

bool target_turnable(const calib::Mechanism& model, int frame) {
  // Two actuators at least: with six or more the target is put at the pose asked (IK); with
  // fewer (the 4-DOF wire robot's branch) it cannot take an arbitrary pose, and its face is
  // turned towards the cameras as far as its joints allow (aim_face).
  return model.task.type == calib::TaskType::kPose && model.task.frame == frame &&
         model.actuated.size() >= 2;
}

bool task_space_sampling_applies(const FeasibilityChecker& checker) {
  return target_turnable(checker.reach().model(), checker.frame()) &&
         !checker.cell().required_cameras().empty();
}

namespace {

// What the candidates are turned towards: the cell's required cameras, the board's centre and
// size in the board frame.
struct FacingCameras {
  std::vector<const CellCamera*> cams;
  std::size_t needed = 0;  // cameras that must see the target (the cell's min_cameras, or all)
  Eigen::Vector3d board_mid = Eigen::Vector3d::Zero();
  double short_side = 0.0;
  const Cell* cell = nullptr;

  explicit FacingCameras(const Cell& c) : cell(&c) {
    for (const int ci : c.required_cameras())
      cams.push_back(&c.cameras.at(static_cast<std::size_t>(ci)));
    needed = static_cast<std::size_t>(std::max(1, c.cameras_needed()));
    const std::vector<Eigen::Vector3d> outline = board_outline(c.target.board);
    for (const Eigen::Vector3d& p : outline) board_mid += p / 4.0;
    short_side = std::min((outline[1] - outline[0]).norm(), (outline[3] - outline[0]).norm());
  }

  // The positions of the required cameras that could see a target centred at `centre` and
  // facing them squarely, whole: the centre inside the image by half the target's image size
  // (plus the border), the target's image at least the minimum size. Empty when fewer than the
  // cell needs (a camera array: two of its cameras; otherwise every required one).
  std::vector<Eigen::Vector3d> eyes_seeing(const Eigen::Vector3d& centre) const {
    std::vector<Eigen::Vector3d> eyes;
    for (const CellCamera* cam : cams) {
      const Eigen::Vector3d pc = cam->world_T_camera.inverse() * centre;
      if (pc.z() <= 0) continue;
      const double fx = cam->model.params.empty() ? 0.0 : cam->model.params[0];
      const double size = fx * short_side / pc.norm();
      if (size < cell->visibility.min_image_size) continue;
      const auto px = vision::project(cam->model, pc);
      if (!px || !vision::in_image(cam->model, *px, cell->margins.image_border + 0.5 * size))
        continue;
      eyes.emplace_back(cam->world_T_camera.translation());
    }
    if (eyes.size() < needed) eyes.clear();
    return eyes;
  }

  Eigen::Vector3d centre_of(const ReachResult& r, int frame) const {
    return r.body_poses[static_cast<std::size_t>(frame)] * cell->target.frame_T_board * board_mid;
  }
};

Eigen::Vector3d mean_of(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) m += p / static_cast<double>(points.size());
  return m;
}

}  // namespace

bool target_turned_by_joints(const calib::Mechanism& model, int frame) {
  return target_turnable(model, frame) && model.actuated.size() < 6;
}

Candidate evaluate_turned_towards_cameras(const FeasibilityChecker& checker,
                                          const Eigen::VectorXd& readings) {
  const ReachChecker& reach = checker.reach();
  const ReachResult r = reach.reach_check(readings);
  if (!r.ok()) return checker.evaluate(readings);
  const FacingCameras facing(checker.cell());
  const Eigen::Vector3d centre = facing.centre_of(r, checker.frame());
  const std::vector<Eigen::Vector3d> eyes = facing.eyes_seeing(centre);
  if (eyes.empty()) return checker.evaluate(readings);  // the visibility test says why
  Eigen::VectorXd lo, hi;
  reach.reading_limits(lo, hi);
  const std::optional<Eigen::VectorXd> aimed =
      aim_face(reach, checker.frame(), checker.cell().target.frame_T_board.linear(), readings, r,
               (mean_of(eyes) - centre).normalized(), lo, hi);
  return checker.evaluate(aimed ? reach.nearest_turn_to_home(*aimed) : readings);
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
  const FacingCameras facing(cell);
  const Eigen::Vector3d& board_mid = facing.board_mid;
  const Eigen::Isometry3d board_T_frame = cell.target.frame_T_board.inverse();

  const bool full_pose = model.actuated.size() >= 6;
  const Eigen::Matrix3d frame_R_board = cell.target.frame_T_board.linear();
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
    std::vector<Eigen::Vector3d> eyes;  // the cameras that can see the sample's target centre
    for (int t = 0; t < kSeedTries; ++t) {
      for (Eigen::Index k = 0; k < lo.size(); ++k) x(k) = lo(k) + u(rng) * (hi(k) - lo(k));
      seed = reach.reach_check(x);
      if (!seed.ok()) continue;
      eyes = facing.eyes_seeing(facing.centre_of(seed, checker.frame()));
      if (!eyes.empty()) break;
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
      // Towards the cameras that see it (every required one, or, in an array, those of the
      // stations it is in front of); the last draw's when none does.
      if (eyes.empty())
        for (const CellCamera* cam : facing.cams)
          eyes.emplace_back(cam->world_T_camera.translation());
      const Eigen::Vector3d n0 = (mean_of(eyes) - centre).normalized();
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
      if (!full_pose) {  // fewer than six actuators: the face turned as far as the joints allow
        const std::optional<Eigen::VectorXd> aimed =
            aim_face(reach, checker.frame(), frame_R_board, x, seed, n, lo, hi);
        if (aimed) {
          c = checker.evaluate(reach.nearest_turn_to_home(*aimed));
        } else {
          c.readings = x;
          c.rejection = Rejection::kNoAssembly;
          c.detail = "turning the board towards the cameras leaves the intended assembly mode";
        }
      } else {  // six or more: the board put at a pose facing the cameras (IK)
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
    }
    if (counts != nullptr) counts->add(c);
    out.push_back(std::move(c));
  }
  return out;
}

}  // namespace robocal::planner
