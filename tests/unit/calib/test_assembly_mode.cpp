// Assembly modes: every FK / IK / closure answer carries a verdict; an answer on
// another mode is re-seeded or refused, never reported as converged; the robot file's declared
// mode is checked against its own home configuration.
#include "calib_test_support.hpp"
#include "mode_sweep.hpp"
#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>

#include <array>
#include <fstream>
#include <random>
#include <sstream>

namespace robocal::calib {
namespace {

using testing::load;

Eigen::Vector3d tool_position(const Mechanism& m, const Eigen::VectorXd& p,
                              const Eigen::VectorXd& readings, const Eigen::VectorXd& passive) {
  return frame_pose(m, p, make_joint_state(m, p, readings, passive), m.tool).translation();
}

TEST(AssemblyMode, IssueReadingsAnswerTheClosedFormOnTheIntendedMode) {
  // The issue's report: these readings came back 0.4 m from the closed form, "converged".
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  for (const Eigen::Vector3d& q : {Eigen::Vector3d(1.2, 0.6, 0.6), Eigen::Vector3d(1.5, 0, 0)}) {
    const auto ref = sweep::nominal_reference(m, p, q);
    ASSERT_TRUE(ref.tool);
    const ClosureResult r = solve_closure(m, p, q);
    ASSERT_TRUE(r.ok()) << to_string(r.status) << " " << r.mode.describe();
    // Both lie near a singular configuration of the loops (the first arm far down): the answer is
    // the intended one, said to be close to where modes meet.
    EXPECT_NE(r.mode.verdict, ModeVerdict::kOther) << r.mode.describe();
    std::printf("%s\n", r.mode.describe().c_str());
    EXPECT_LE((tool_position(m, p, q, r.passive) - *ref.tool).norm(), 1e-9);
  }
}

TEST(AssemblyMode, CoarseSweepOfEveryParallelRobotNeverAnswersAnotherModeSilently) {
  // 5 values per actuator over its whole range (limits included), nominal + 3 draws at 5x the
  // file's tolerances. The dense sweep (20 per actuator, 20 draws) is bench_assembly_modes.
  for (const char* file : {"rotary_delta.yaml", "linear_delta.yaml", "gantry_tau.yaml",
                           "four_bar.yaml", "wire_robot_branch.yaml"}) {
    const Mechanism m = load(file);
    const int values = m.actuated.size() == 1 ? 21 : 5;  // a single crank: a finer line
    const sweep::Counts c = sweep::sweep_robot(m, values, 3, 5.0);
    EXPECT_EQ(c.silent_wrong, 0) << file;
    EXPECT_LE(c.max_error, 1e-9) << file;
    // Most intended answers are checked against the reference (the rest: the perturbed
    // reference's continuation could not follow the branch, near a singularity of the nominal).
    EXPECT_GE(c.compared, 3 * c.intended / 4) << file;
    std::printf(
        "%s: %ld configurations, %ld intended (%ld compared, max error %.2g m), %ld "
        "ambiguous, %ld refused (%ld with a reference clear of every boundary), %ld not "
        "closing\n",
        file, c.configurations, c.intended, c.compared, c.max_error, c.ambiguous, c.refused_other,
        c.refused_with_clear_reference, c.not_closed);
  }
}

TEST(AssemblyMode, WarmStartOnTheMirroredPlateIsRecognisedAndReSeeded) {
  // The plate just above the plane of the elbows (the other trilateration solution) is a closed
  // configuration of the same readings, across the type-II singular boundary.
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  const Eigen::Vector3d q(0.3, 0.5, 0.2);
  ClosureOptions plain;
  plain.enforce_mode = false;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-M_PI, M_PI);
  Eigen::VectorXd other;
  ModeCheck other_mode;
  for (int k = 0; k < 400 && other.size() == 0; ++k) {
    Eigen::VectorXd seed = m.home_passive();
    for (Eigen::Index i = 0; i < seed.size(); ++i) seed[i] += u(rng);
    const ClosureResult r = solve_closure(m, p, q, seed, plain);
    if (r.ok() && r.mode.verdict == ModeVerdict::kOther &&
        r.mode.invariant.find("plate_below_elbows") != std::string::npos) {
      other = r.passive;
      other_mode = r.mode;
    }
  }
  ASSERT_GT(other.size(), 0) << "no closed configuration with the plate above the elbows found";
  EXPECT_LT(other_mode.margin, 0.0);
  const auto ref = sweep::nominal_reference(m, p, q);
  ASSERT_TRUE(ref.tool);
  EXPECT_GT((tool_position(m, p, q, other) - *ref.tool).norm(), 0.1);
  // The public check agrees with the solver's.
  const ModeCheck check = check_assembly_mode(m, p, make_joint_state(m, p, q, other));
  EXPECT_EQ(check.verdict, ModeVerdict::kOther);
  EXPECT_NE(check.invariant.find("plate_below_elbows"), std::string::npos);
  // Warm-started there, the solver does not report it: it re-seeds to the intended answer.
  const ClosureResult fixed = solve_closure(m, p, q, other);
  ASSERT_TRUE(fixed.ok());
  EXPECT_EQ(fixed.mode.verdict, ModeVerdict::kIntended);
  EXPECT_LE((tool_position(m, p, q, fixed.passive) - *ref.tool).norm(), 1e-9);
}

TEST(AssemblyMode, CrossedRodPairIsOtherNamingItsParallelogram) {
  // Force rod pairs into the crossed parallelogram: closures solved (mode checks off) from seeds
  // with the passive joints scrambled. Every closed answer whose rod pair is crossed — judged by
  // plain geometry written here, the pair's lower segment pointing against its upper one — must
  // be `other`, naming that arm's parallelogram invariant.
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  // An arm stretched far down and its neighbours up: the crossed pairs close there (the sweep's
  // refusals name them).
  const Eigen::Vector3d q(1.5, -0.9, 1.5);
  const ClosureResult good = solve_closure(m, p, q);
  ASSERT_TRUE(good.ok());
  ClosureOptions plain;
  plain.enforce_mode = false;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-M_PI, M_PI);
  // Per arm: upper ends of its two rods, lower ends of its two rods.
  const std::vector<std::array<const char*, 5>> arms = {
      {"arm1_parallelogram", "body6", "body16", "body7", "body17"},
      {"arm2_parallelogram", "body19", "body22", "body20", "body23"},
      {"arm3_parallelogram", "body25", "body28", "body26", "body29"}};
  int crossed = 0;
  for (int k = 0; k < 300; ++k) {
    Eigen::VectorXd seed = good.passive;
    for (Eigen::Index i = 0; i < seed.size(); ++i) seed[i] += u(rng);
    const ClosureResult r = solve_closure(m, p, q, seed, plain);
    if (!r.ok()) continue;
    std::vector<Eigen::Isometry3d> poses;
    body_poses(m, p, make_joint_state(m, p, q, r.passive), poses);
    const auto at = [&](const char* b) {
      return Eigen::Vector3d(poses[static_cast<std::size_t>(m.body_index(b))].translation());
    };
    for (const auto& arm : arms) {
      const Eigen::Vector3d upper = at(arm[2]) - at(arm[1]);
      const Eigen::Vector3d lower = at(arm[4]) - at(arm[3]);
      if (upper.dot(lower) > -0.05 * upper.norm() * lower.norm()) continue;
      ++crossed;
      EXPECT_EQ(r.mode.verdict, ModeVerdict::kOther);
      EXPECT_NE(r.mode.invariant.find(arm[0]), std::string::npos) << r.mode.invariant;
      // The enforcing solver, warm-started there, never reports it: it comes back to the
      // intended mode (or says it is near a boundary).
      const ClosureResult fixed = solve_closure(m, p, q, r.passive);
      ASSERT_TRUE(fixed.ok());
      EXPECT_NE(fixed.mode.verdict, ModeVerdict::kOther);
    }
  }
  EXPECT_GT(crossed, 0) << "no closed configuration with a crossed rod pair found";
}

// Closed configurations of a model at fixed readings, found by brute force written here: plain
// Gauss-Newton with a central-difference Jacobian of the open-tree closure residual from many
// random seeds (no ClosureSolver, no seeding strategy, no verdict), kept when every declared
// invariant has its declared sign with at least the file's ambiguity band, distinct by tool
// position (> 1e-6 m apart).
std::vector<Eigen::Vector3d> declared_mode_census(const Mechanism& m, const Eigen::VectorXd& p,
                                                  const Eigen::VectorXd& q, int seeds) {
  const auto residual = [&](const Eigen::VectorXd& x) {
    return closure_residual(m, p, make_joint_state(m, p, q, x));
  };
  std::mt19937 rng(2026);
  std::uniform_real_distribution<double> u(-M_PI, M_PI);
  std::vector<Eigen::Vector3d> found;
  for (int k = 0; k < seeds; ++k) {
    Eigen::VectorXd x = m.home_passive();
    for (Eigen::Index i = 0; i < x.size(); ++i) x[i] += u(rng);
    Eigen::VectorXd r = residual(x);
    for (int it = 0; it < 60 && r.cwiseAbs().maxCoeff() > 1e-13; ++it) {
      Eigen::MatrixXd J(r.size(), x.size());
      for (Eigen::Index j = 0; j < x.size(); ++j) {
        Eigen::VectorXd a = x, b = x;
        a[j] += 1e-7;
        b[j] -= 1e-7;
        J.col(j) = (residual(a) - residual(b)) / 2e-7;
      }
      // Damped step, halved until the residual drops.
      const Eigen::VectorXd dx =
          (J.transpose() * J + 1e-9 * Eigen::MatrixXd::Identity(x.size(), x.size()))
              .ldlt()
              .solve(-J.transpose() * r);
      double step = 1.0;
      Eigen::VectorXd trial = x + dx, rt = residual(trial);
      while (rt.norm() >= r.norm() && step > 1e-4) {
        step *= 0.5;
        trial = x + step * dx;
        rt = residual(trial);
      }
      if (rt.norm() >= r.norm()) break;
      x = trial;
      r = rt;
    }
    if (r.cwiseAbs().maxCoeff() > 1e-10) continue;
    const JointState s = make_joint_state(m, p, q, x);
    std::vector<Eigen::Isometry3d> poses;
    body_poses(m, p, s, poses);
    bool declared = true;
    for (const ModeInvariant& inv : m.assembly_mode.invariants)
      declared =
          declared && inv.sign * invariant_value(inv, poses, s, m) >= m.assembly_mode.ambiguity;
    if (!declared) continue;
    const Eigen::Vector3d tool = poses[static_cast<std::size_t>(m.tool)].translation();
    bool seen = false;
    for (const Eigen::Vector3d& f : found) seen = seen || (f - tool).norm() < 1e-6;
    if (!seen) found.push_back(tool);
  }
  return found;
}

TEST(AssemblyMode, PerturbedDeltaNearItsDesignSingularityIsNotCalledIntended) {
  // A formerly silent wrong-mode case of bench_assembly_modes: the first perturbed draw of the
  // sweep (5x the file's tolerances, seed 15) at shoulder angles (-30, 90, 60) deg, where the
  // design Delta's loops are near singular (conditioning 0.004). The perturbed loops close there
  // in many configurations that all satisfy every declared invariant, centimetres apart; the old
  // solver answered one of them (the nearest to its closed-form seed) as `intended`, 3.5 cm from
  // the answer the design's turns into under the perturbation.
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd nominal = m.nominal_parameters();
  std::mt19937 rng(15);
  const Eigen::VectorXd p = sweep::perturbed(m, 5.0, rng);
  const Eigen::VectorXd q =
      readings_from_joint_values(m, nominal, Eigen::Vector3d(-M_PI / 6, M_PI / 2, M_PI / 3));
  const std::vector<Eigen::Vector3d> census = declared_mode_census(m, p, q, 150);
  double spread = 0.0;
  for (const Eigen::Vector3d& a : census)
    for (const Eigen::Vector3d& b : census) spread = std::max(spread, (a - b).norm());
  ASSERT_GE(census.size(), 2U) << "the intended mode is unique here: nothing to test";
  EXPECT_GT(spread, 0.01);
  // The intended mode is not one configuration here: the library must say so (ambiguous, naming
  // the design's singularity), not pick one and call it intended.
  const ClosureResult r = solve_closure(m, p, q);
  ASSERT_TRUE(r.ok()) << to_string(r.status);
  EXPECT_EQ(r.mode.verdict, ModeVerdict::kAmbiguous) << r.mode.describe();
  EXPECT_NE(r.mode.invariant.find("design_"), std::string::npos) << r.mode.invariant;
  // Its answer is one of the closed configurations the brute force finds.
  const Eigen::Vector3d tool = tool_position(m, p, q, r.passive);
  double nearest = 1e300;
  for (const Eigen::Vector3d& f : census) nearest = std::min(nearest, (f - tool).norm());
  std::printf(
      "%zu declared-mode configurations, %.3g m apart at most; library %s, %.3g m from the "
      "nearest\n",
      census.size(), spread, r.mode.describe().c_str(), nearest);
}

TEST(AssemblyMode, InverseKinematicsVerdictCarriesTheClosureConditioning) {
  // Forward kinematics calls an answer ambiguous where the loops are nearly singular even when
  // every invariant keeps its sign; inverse kinematics must say the same of the same
  // configuration (it used to answer `intended` there on the design model). The reference is the
  // public exact check on the FK state.
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  const double gate = m.assembly_mode.min_conditioning;
  int singular = 0, clear = 0;
  for (double a = -0.6; a <= 1.5; a += 0.05) {
    for (double b = -0.6; b <= 1.5; b += 0.3) {
      const Eigen::VectorXd q = readings_from_joint_values(m, p, Eigen::Vector3d(a, b, 0.2));
      const ClosureResult fk = solve_closure(m, p, q);
      if (!fk.ok()) continue;
      const ModeCheck exact = check_assembly_mode(m, p, make_joint_state(m, p, q, fk.passive));
      // Only clear cases: conditioning off the gate by 10 %, every invariant clear of its band.
      const bool by_conditioning =
          exact.verdict == ModeVerdict::kAmbiguous && exact.invariant == "closure_conditioning";
      const bool singular_case = by_conditioning && exact.conditioning < 0.9 * gate;
      const bool clear_case = exact.intended() && exact.conditioning > 1.1 * gate;
      if (!singular_case && !clear_case) continue;
      TaskTarget target;
      target.pose.translation() = tool_position(m, p, q, fk.passive);
      const IkResult ik = solve_ik(m, p, target);
      ASSERT_TRUE(ik.ok()) << "readings " << q.transpose() << ": " << to_string(ik.status);
      ASSERT_LE((ik.actuator_readings - q).cwiseAbs().maxCoeff(), 1e-6) << q.transpose();
      EXPECT_EQ(ik.mode.verdict, exact.verdict)
          << "readings " << q.transpose() << ": IK " << ik.mode.describe() << ", exact "
          << exact.describe();
      if (singular_case)
        EXPECT_NEAR(ik.mode.conditioning, exact.conditioning, 1e-3 * exact.conditioning);
      else
        EXPECT_GE(ik.mode.conditioning, gate);
      (singular_case ? singular : clear)++;
    }
  }
  // Both kinds must have been seen, or the test proves nothing.
  EXPECT_GT(singular, 0);
  EXPECT_GT(clear, 0);
  std::printf("%d nearly singular and %d clear configurations agree\n", singular, clear);
}

TEST(AssemblyMode, SerialJointJustAcrossItsBoundaryFlipsTheVerdict) {
  // Modular arm, elbow_left = sin(q2) > 0: q2 = +0.3 intended, +0.01 ambiguous (within the
  // 0.02 band), -0.03 just across the boundary -> other, naming elbow_left.
  const Mechanism m = load("modular_arm.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  const auto verdict_at = [&](double q2) {
    const Eigen::Vector3d q(0.2, q2, 0.1);
    const ClosureResult r = solve_closure(m, p, q);
    EXPECT_TRUE(r.ok());  // a serial arm has one answer: reported with its verdict
    return r.mode;
  };
  EXPECT_EQ(verdict_at(0.3).verdict, ModeVerdict::kIntended);
  const ModeCheck near = verdict_at(0.01);
  EXPECT_EQ(near.verdict, ModeVerdict::kAmbiguous);
  EXPECT_NEAR(near.distance, std::sin(0.01), 1e-12);
  const ModeCheck across = verdict_at(-0.03);
  EXPECT_EQ(across.verdict, ModeVerdict::kOther);
  EXPECT_EQ(across.invariant, "elbow_left");
}

TEST(AssemblyMode, SerialIkPicksTheDeclaredBranch) {
  // Targets reached by configurations on OTHER branches (elbow right; UR5 elbow down / wrist
  // flipped): IK answers the same target on the declared branch.
  {
    const Mechanism m = load("modular_arm.yaml");
    const Eigen::VectorXd p = m.nominal_parameters();
    const Eigen::Vector3d q(0.4, -1.1, 0.05);
    TaskTarget target;
    target.pose.translation() = forward_kinematics(m, p, q, m.task.frame).pose.translation();
    const IkResult ik = solve_ik(m, p, target);
    ASSERT_TRUE(ik.ok()) << to_string(ik.status);
    EXPECT_EQ(ik.mode.verdict, ModeVerdict::kIntended);
    EXPECT_GT(std::sin(ik.actuator_q[1]), 0.02);
    EXPECT_LE((forward_kinematics(m, p, ik.actuator_readings, m.task.frame).pose.translation() -
               target.pose.translation())
                  .norm(),
              1e-9);
  }
  {
    const Mechanism m = load("ur5.yaml");
    const Eigen::VectorXd p = m.nominal_parameters();
    Eigen::VectorXd q(6);
    q << 0.3, -1.9, -1.2, -1.0, -1.2, 0.4;  // elbow down, wrist flipped
    const ForwardResult fk = forward_kinematics(m, p, q, m.task.frame);
    ASSERT_EQ(fk.closure.mode.verdict, ModeVerdict::kOther);
    TaskTarget target;
    target.pose = fk.pose;
    const IkResult ik = solve_ik(m, p, target);
    ASSERT_TRUE(ik.ok()) << to_string(ik.status) << " " << ik.mode.describe();
    EXPECT_EQ(ik.mode.verdict, ModeVerdict::kIntended);
    const ForwardResult back = forward_kinematics(m, p, ik.actuator_readings, m.task.frame);
    EXPECT_LE((back.pose.translation() - target.pose.translation()).norm(), 1e-9);
    EXPECT_LE(rotation_error(back.pose.linear(), target.pose.linear()).norm(), 1e-9);
  }
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(AssemblyMode, DeclaredModeContradictingHomeIsALoadErrorWithFileAndLine) {
  std::string text = read_text(testing::robot_path("rotary_delta.yaml"));
  const std::string good =
      "{name: arm2_parallelogram, type: parallel, bodies: [body19, body22, body20, body23], "
      "sign: 1}";
  const auto at = text.find(good);
  ASSERT_NE(at, std::string::npos);
  text.replace(at, good.size(),
               "{name: arm2_parallelogram, type: parallel, bodies: [body19, body22, body20, "
               "body23], sign: -1}");
  const int line = 1 + static_cast<int>(std::count(text.begin(), text.begin() + at, '\n'));
  try {
    (void)parse_robot_yaml(text, "bad_delta.yaml");
    FAIL() << "a mode contradicting the home configuration was accepted";
  } catch (const RobotFileError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("bad_delta.yaml:" + std::to_string(line) + ":"), std::string::npos) << what;
    EXPECT_NE(what.find("arm2_parallelogram"), std::string::npos) << what;
    EXPECT_NE(what.find("home"), std::string::npos) << what;
  }
  // A home configuration ON the boundary is refused too (modular arm with joint 2 home 0).
  std::string arm = read_text(testing::robot_path("modular_arm.yaml"));
  const auto h = arm.find("home: 1.0");
  ASSERT_NE(h, std::string::npos);
  arm.replace(h, 9, "home: 0.0");
  EXPECT_THROW((void)parse_robot_yaml(arm, "arm.yaml"), RobotFileError);
  // Malformed declarations name their line too.
  std::string bad = read_text(testing::robot_path("linear_delta.yaml"));
  const auto t = bad.find("type: triple");
  ASSERT_NE(t, std::string::npos);
  bad.replace(t, 12, "type: twist");
  try {
    (void)parse_robot_yaml(bad, "ld.yaml");
    FAIL();
  } catch (const RobotFileError& e) {
    EXPECT_NE(std::string(e.what()).find("side, turn, parallel, triple, joint or tilt"),
              std::string::npos)
        << e.what();
  }
}

TEST(AssemblyMode, EveryLibraryRobotDeclaresAModeItsHomeSatisfies) {
  for (const auto& robot : testing::library()) {
    const Mechanism m = load(robot.file);
    EXPECT_FALSE(m.assembly_mode.invariants.empty()) << robot.file;
    const JointState home = home_joint_state(m);
    const ModeCheck c = check_assembly_mode(m, m.nominal_parameters(), home);
    EXPECT_EQ(c.verdict, ModeVerdict::kIntended) << robot.file << ": " << c.describe();
  }
}

TEST(AssemblyMode, PerturbedDeltaWarmAndInverseAnswersAreWhatColdForwardKinematicsGives) {
  // Near the design's singular set a perturbed Delta's loops close in several configurations that
  // all satisfy the declared invariants; the one that counts is the cold FK answer (the design's,
  // followed to the perturbed parameters). A warm solve seeded from the design's configuration and
  // the IK of the cold answer's tool position must come back to that same configuration (or say
  // they cannot, as ambiguous or refused): the IK's readings, sent to the robot, must put the tool
  // on the target by FK.
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd nominal = m.nominal_parameters();
  std::mt19937 rng(15);
  int warm_compared = 0, warm_wrong = 0, ik_compared = 0, ik_wrong = 0;
  for (int draw = 0; draw < 3; ++draw) {
    const Eigen::VectorXd p = sweep::perturbed(m, 5.0, rng);
    for (const Eigen::VectorXd& q : sweep::grid(m, nominal, 8)) {
      const ClosureResult cold = solve_closure(m, p, q);
      if (!cold.ok() || !cold.mode.acceptable()) continue;
      const ClosureResult design = solve_closure(m, nominal, q);
      if (design.ok()) {
        const ClosureResult warm = solve_closure(m, p, q, design.passive);
        if (warm.ok() && warm.mode.intended()) {
          ++warm_compared;
          if ((tool_position(m, p, q, warm.passive) - tool_position(m, p, q, cold.passive)).norm() >
              1e-9)
            ++warm_wrong;
        }
      }
      TaskTarget target;
      target.pose.translation() = tool_position(m, p, q, cold.passive);
      const IkResult ik = solve_ik(m, p, target);
      if (!ik.ok() || !ik.mode.intended()) continue;
      ++ik_compared;
      const ClosureResult fk = solve_closure(m, p, ik.actuator_readings);
      if (!fk.ok() ||
          (tool_position(m, p, ik.actuator_readings, fk.passive) - target.pose.translation())
                  .norm() > 1e-9)
        ++ik_wrong;
    }
  }
  std::printf("warm: %d compared, %d elsewhere; IK: %d compared, %d off the target by FK\n",
              warm_compared, warm_wrong, ik_compared, ik_wrong);
  EXPECT_GT(warm_compared, 400);
  EXPECT_GT(ik_compared, 400);
  EXPECT_EQ(warm_wrong, 0);
  EXPECT_EQ(ik_wrong, 0);
}

TEST(AssemblyMode, AWarmSeedNewtonTravelsFromIsCheckedAgainstTheColdAnswer) {
  // A formerly silent wrong-mode case of bench_assembly_modes --warm: the 17th perturbed draw of
  // the sweep (5x the file's tolerances, seed 15), 20 values per actuator, seeded with the design's
  // answer at the same readings (as compensation seeds). The design is near a singularity of its
  // loops there (conditioning 0.0015), so the cold answer is ambiguous; the warm solve, far from
  // any singularity of its own (conditioning 0.066), took seven Newton steps from that seed to a
  // configuration that keeps every declared sign, its tool 45 mm from the sweep's reference (the
  // design's answer continued to the perturbation in small steps), and called it intended. Fails
  // on the old solver (warm `intended`, cold `ambiguous`).
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd nominal = m.nominal_parameters();
  std::mt19937 rng(15);
  Eigen::VectorXd p;
  for (int draw = 0; draw < 17; ++draw) p = sweep::perturbed(m, 5.0, rng);
  const Eigen::Vector3d wanted(-0.633830, 0.744061, 1.295218);
  Eigen::VectorXd q;
  for (const Eigen::VectorXd& c : sweep::grid(m, nominal, 20))
    if (q.size() == 0 || (c - wanted).norm() < (q - wanted).norm()) q = c;
  ASSERT_LT((q - wanted).norm(), 1e-5);
  const ClosureResult cold = solve_closure(m, p, q);
  ASSERT_TRUE(cold.ok() && cold.mode.acceptable()) << cold.mode.describe();
  const ClosureResult design = solve_closure(m, nominal, q);
  ASSERT_TRUE(design.ok());
  const ClosureResult warm = solve_closure(m, p, q, design.passive);
  ASSERT_TRUE(warm.ok()) << to_string(warm.status);
  const double apart =
      (tool_position(m, p, q, warm.passive) - tool_position(m, p, q, cold.passive)).norm();
  // Intended only where it is the cold answer; elsewhere it must say it is not sure.
  EXPECT_TRUE(!warm.mode.intended() || apart < 1e-9)
      << "warm answer " << warm.mode.describe() << ", " << apart << " m from the cold one, after "
      << warm.iterations << " steps";
  EXPECT_EQ(warm.mode.verdict, cold.mode.verdict) << warm.mode.describe();
}

TEST(AssemblyMode, IkSolverAlongAPathAnswersAsTheOneShotSolver) {
  // The IK solver keeps state across solves (the evaluator, the design check's closure solver, the
  // conditioning carried from answer to answer). Along warm paths of a perturbed Delta, through
  // its nearly singular region and the design check's band, each answer must be the one the
  // one-shot solve_ik gives for the same target and seed: status, readings, verdict, and the
  // conditioning on the same side of the ambiguity gate and (perturbed model) of the design
  // check's threshold.
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd nominal = m.nominal_parameters();
  const double gate = m.assembly_mode.min_conditioning;
  // The design check's threshold: kDesignCheckMargin (calib/src/mode_check.hpp) times the gate.
  const double design_check = 2.5 * gate;
  std::mt19937 rng(16);
  int compared = 0, ambiguous = 0, design_band = 0;
  for (int draw = 0; draw < 2; ++draw) {
    const Eigen::VectorXd p = draw == 0 ? nominal : sweep::perturbed(m, 5.0, rng);
    for (double b = -0.6; b <= 1.5; b += 0.7) {
      IkSolver solver(m, p);
      IkSeed seed;
      // Tool positions along a line of readings, 5 mrad apart on the first actuator.
      for (double a = -0.6; a <= 1.5; a += 0.005) {
        const Eigen::VectorXd q = readings_from_joint_values(m, p, Eigen::Vector3d(a, b, 0.2));
        const ClosureResult fk = solve_closure(m, p, q);
        if (!fk.ok() || !fk.mode.acceptable()) {
          seed = {};
          continue;
        }
        TaskTarget target;
        target.pose.translation() = tool_position(m, p, q, fk.passive);
        const IkResult once = solve_ik(m, p, target, seed);
        const IkResult kept = solver.solve(target, seed);
        ASSERT_EQ(kept.status, once.status) << "a " << a << " b " << b;
        ASSERT_EQ(kept.mode.verdict, once.mode.verdict)
            << "a " << a << " b " << b << ": " << kept.mode.describe() << " vs "
            << once.mode.describe();
        if (!once.ok()) {
          seed = {};
          continue;
        }
        EXPECT_EQ(kept.mode.invariant, once.mode.invariant) << "a " << a << " b " << b;
        EXPECT_LE((kept.actuator_readings - once.actuator_readings).cwiseAbs().maxCoeff(), 1e-12)
            << "a " << a << " b " << b;
        // The thresholds that decide something: the gate, and for a perturbed model the design
        // check's (above them the value may be an estimate or a proved lower bound).
        for (const double threshold : {gate, draw == 0 ? gate : design_check})
          EXPECT_EQ(kept.mode.conditioning < threshold, once.mode.conditioning < threshold)
              << "a " << a << " b " << b << ": " << kept.mode.conditioning << " vs "
              << once.mode.conditioning;
        ++compared;
        ambiguous += once.mode.verdict == ModeVerdict::kAmbiguous ? 1 : 0;
        design_band +=
            draw == 1 && once.mode.conditioning >= gate && once.mode.conditioning < design_check;
        seed = {once.actuator_q, once.passive};
      }
    }
  }
  std::printf("%d answers compared, %d ambiguous, %d in the design check's band (perturbed)\n",
              compared, ambiguous, design_band);
  // The paths must have crossed both regions, or the test proves little.
  EXPECT_GT(compared, 500);
  EXPECT_GT(ambiguous, 0);
  EXPECT_GT(design_band, 0);
}

}  // namespace
}  // namespace robocal::calib
