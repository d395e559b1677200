#pragma once
// The mechanism model shared by serial arms and parallel robots: a tree of bodies rooted at the
// world frame, plus closures that cut every kinematic loop, plus ONE flat vector of named
// geometric parameters (joint geometry, encoder offset/scale, base/tool frames, rod lengths).
//
// Conventions (used everywhere in robocal::calib):
// - Lengths in metres, angles in radians.
// - A pose (Eigen::Isometry3d) of a frame maps coordinates in that frame to world (root)
//   coordinates: x_world = R * x_frame + p.
// - Every body's frame is reached from its predecessor's frame by a sequence of elementary
//   transforms (ElementaryOp): Rx/Ry/Rz (active, right-multiplied) and Tx/Ty/Tz (translation
//   along the current local axis). Exactly one op of a moving body carries the joint variable
//   (revolute: a rotation, prismatic: a translation); its value is param + sign * q.
//   Each convention (MCPC, DH, Craig MDH, Hayati, xyz+rpy) expands to such a sequence; see
//   convention_ops() in robot_file.hpp and testdata/robots/README.md.
// - Rotation increments (Jacobians, rotation errors) are world-frame (spatial) small-angle
//   vectors w: R' = Exp([w]x) * R. Rotation errors between two frames use the rotation vector of
//   R_a * R_b^T, never Euler-angle differences.
// - Actuator readings are what the controller reports (counts, or already rad/m); the joint
//   variable is q = encoder_scale * reading + encoder_offset (both are named parameters).
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <string>
#include <vector>

namespace robocal::calib {

// Kind of motion a body's joint allows relative to its predecessor.
enum class JointType : std::uint8_t {
  kRevolute,   // rotation about the joint op's axis
  kPrismatic,  // translation along the joint op's axis
  kFixed,      // no motion (auxiliary frames, spherical cut frames, welded links)
};

// What the closure solver does with a joint.
enum class JointRole : std::uint8_t {
  kActuated,   // read by an encoder: an input of forward kinematics
  kPassive,    // unknown solved by closure (forward kinematics) or by IK
  kCut,        // the body is one end of a closure (e.g. spherical cut); no joint variable
  kAuxiliary,  // fixed frame: base, tool, marker, attachment point
};

enum class OpKind : std::uint8_t { kRotX, kRotY, kRotZ, kTransX, kTransY, kTransZ };

// One elementary transform. value = (param >= 0 ? params[param] : 0) + (joint ? sign * q : 0).
struct ElementaryOp {
  OpKind kind = OpKind::kRotZ;
  int param = -1;      // index into Mechanism::parameters, -1 = constant 0
  bool joint = false;  // carries the body's joint variable
  double sign = 1.0;   // joint direction (URDF axis "-z" etc.)
};

enum class ParamUnit : std::uint8_t {
  kLength,  // metres
  kAngle,   // radians
  kScale,   // dimensionless (encoder scale: joint units per reading unit)
};

// What a parameter describes, so identification can group/report them.
enum class ParamGroup : std::uint8_t {
  kJointGeometry,  // convention parameters of a moving body or a link
  kFrame,          // geometry of an auxiliary or cut frame (base, tool, marker, attachment)
  kEncoderOffset,  // q = scale * reading + offset
  kEncoderScale,
  kRodLength,  // distance closures (rods, cables)
};

struct Parameter {
  std::string name;    // stable, e.g. "body26.d1", "rod5.length", "base.z", "body2.encoder_offset"
  double value = 0.0;  // nominal value from the robot file
  bool free = true;    // identification may estimate it (robot file: free:/fixed: lists)
  // Exact by construction (robot file `exact:`; implies held fixed): a real robot cannot differ
  // from the drawing here, so a simulation's unmodelled error leaves it alone (the offsets
  // between the three revolute axes that model a ball joint, which meet at its centre).
  bool exact = false;
  double sigma = 0.0;  // prior tolerance (1-sigma) for identification; > 0
  ParamUnit unit = ParamUnit::kLength;
  ParamGroup group = ParamGroup::kJointGeometry;
  int body = -1;     // owning body (-1 for rods: see closure)
  int closure = -1;  // owning closure for rod lengths
  int line = 0;      // 1-based line in the robot file (0 = generated)
  // Plain words a technician reads ("rod 26 length", "shoulder 1 encoder zero"): robot file
  // `labels:` (testdata/robots/README.md, "Labels"); empty when the file gives none.
  std::string label;
};

// What a person reads for a parameter: its label when the robot file gives one, else its name.
const std::string& display_name(const Parameter& parameter);

enum class ShapeKind : std::uint8_t { kCapsule, kBox };

// Collision geometry in the owning body's frame (for the planner).
struct CollisionShape {
  ShapeKind kind = ShapeKind::kCapsule;
  // Capsule: segment a-b with radius.  Box: centre = a, half extents = half_size, orientation.
  Eigen::Vector3d a = Eigen::Vector3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  double radius = 0.0;
  Eigen::Vector3d half_size = Eigen::Vector3d::Zero();
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
};

struct JointLimits {
  double lower = -1e300;  // joint units (rad or m), applied to q (after the encoder model)
  double upper = 1e300;
  double cone = 0.0;  // ball-joint cone half-angle for spherical cuts (0 = unlimited)
  // The drive's rated speed and force (robot file `velocity:` in rad/s or m/s, `effort:` in N m
  // or N), for exports that carry them (URDF); 0 = the file does not say.
  double velocity = 0.0;
  double effort = 0.0;
};

struct Body {
  std::string name;
  int parent = -1;  // index of the predecessor body, -1 = world
  JointType joint = JointType::kFixed;
  JointRole role = JointRole::kAuxiliary;
  std::string convention;         // "mcpc", "dh", "mdh", "hayati", "xyz_rpy"
  std::vector<ElementaryOp> ops;  // predecessor frame -> this frame
  int joint_op = -1;              // index into ops of the joint op, -1 for fixed bodies
  int actuator = -1;              // index into Mechanism::actuated, -1 if not actuated
  int passive = -1;               // index into Mechanism::passive, -1 if not passive
  int encoder_scale_param = -1;   // actuated bodies only
  int encoder_offset_param = -1;  // actuated bodies only
  JointLimits limits;
  double home = 0.0;  // joint value used as the generic seed (q, joint units)
  std::vector<CollisionShape> collision;
  int subtree_end = 0;  // bodies [index, subtree_end) are this body and its descendants
  int line = 0;
};

enum class ClosureType : std::uint8_t {
  kPose,          // frames coincide (6 rows: position, rotation vector of R_a R_b^T)
  kPosition,      // origins coincide: spherical cut (3 rows)
  kPositionAxis,  // origins and z axes coincide: revolute cut (5 rows)
  kDistance,      // |p_a - p_b| = length parameter: rod or cable (1 row)
};

struct Closure {
  std::string name;
  ClosureType type = ClosureType::kPosition;
  int body_a = -1;
  int body_b = -1;
  int length_param = -1;  // kDistance only
  int line = 0;
};

int closure_rows(ClosureType type);

// Task coordinates for inverse kinematics.
enum class TaskType : std::uint8_t {
  kPosition,  // position of the task frame (3)
  kPose,      // full pose of the task frame (6); least squares for < 6-DOF robots
  kJoint,     // value of one joint (e.g. four-bar output angle) (1)
};

struct TaskSpace {
  TaskType type = TaskType::kPose;
  int frame = -1;  // body index of the task frame (default: tool frame)
  int joint = -1;  // body index of the joint for kJoint
};

// Closed forms the library knows; used as seeds (the generic solver does the exact work).
enum class ClosedFormKind : std::uint8_t { kNone, kRotaryDelta, kLinearDelta, kGantryTau };

struct ClosedFormSpec {
  ClosedFormKind kind = ClosedFormKind::kNone;
  // Rotary Delta: base radius, upper arm, rod, plate radius, arm angles (rad) about world z.
  // The tool (task frame) origin is the plate centre.
  double base_radius = 0.0, upper_arm = 0.0, rod = 0.0, plate_radius = 0.0;
  std::vector<double> arm_angles;
  // Linear delta / Gantry-Tau: per arm i, ||A_i + q_i * v_i - (T + c_i)|| = L_i, with q_i the
  // actuator joint value, T the tool position and c_i the platform attachment offset.
  std::vector<Eigen::Vector3d> rail_origin, rail_direction, platform_offset;
  std::vector<double> link_length;
  // Which of the two trilateration solutions: the one with smaller (-1) or larger (+1)
  // coordinate along this world direction.
  Eigen::Vector3d branch_direction = Eigen::Vector3d::UnitZ();
  double branch_sign = -1.0;
};

// The working volume the robot is specified over (robot file `workspace:`): poses sampled for
// calibration design and validation stay inside it. min_task_conditioning bounds
// σ_min/σ_max of d(task-frame position)/d(actuated joint values) (the dexterity / local
// conditioning index); 0 = the whole reachable set.
struct WorkspaceSpec {
  double min_task_conditioning = 0.0;
  int line = 0;
};

// The intended assembly mode (robot file `assembly_mode:`; rule in testdata/robots/README.md and
// assembly_mode.hpp): sign invariants of the loops and of the serial chain that a cheap check
// evaluates on the body poses. Each invariant is a normalised value in [-1, 1] whose sign tells
// the modes apart; it passes through 0 where two modes meet (a singular configuration).
enum class InvariantKind : std::uint8_t {
  kSide,      // axis (in frame bodies[0]) . unit(p[bodies[1]] - p[bodies[0]])
  kTurn,      // axis of frame bodies[0] . unit(p1 - p0) x unit(p2 - p0): turning sense of 3 points
  kParallel,  // unit(p1 - p0) . unit(p3 - p2): a rod pair is a parallelogram (+) or crossed (-)
  kTriple,    // det[unit(p1 - p0), unit(p3 - p2), unit(p5 - p4)]: side of three rods' plane
  kJoint,     // sin(q) of a revolute joint (q for a prismatic one): elbow / wrist sign
  kTilt,      // (cos t - cos max_angle) / (1 - cos max_angle), clamped to [-1, 1], with t the angle
              // between `axis` in frame bodies[0] and in frame bodies[1]: a platform stays within
              // max_angle of its designed orientation (plate tilt modes of a perturbed Delta)
};

struct ModeInvariant {
  std::string name;
  InvariantKind kind = InvariantKind::kSide;
  std::vector<int> bodies;  // frames the invariant reads (count depends on kind)
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // kSide: direction in frame bodies[0]
  double max_angle = 0.0;                           // kTilt only (rad)
  double sign = 1.0;  // declared sign of the value on the intended mode
  int line = 0;
};

struct AssemblyModeSpec {
  std::vector<ModeInvariant> invariants;  // empty: the file declares no mode
  // |value| below which an invariant cannot tell the modes apart (ambiguous verdict).
  double ambiguity = 0.02;
  // sigma_min / sigma_max of the closure's constraint Jacobian (d closure / d passive joints)
  // below which a closed answer is ambiguous: near a singularity of the loops, where modes the
  // invariants do not separate (e.g. a Delta plate free to tilt) meet.
  double min_conditioning = 0.01;
  int line = 0;
};

// How closely a geometric model can follow this robot at best: the RMS, per axis, of what no
// kinematic parameter explains (elastic deflection, gear runout, thermal drift, a joint's play).
// The fit gate (fit_gate.hpp) allows fit residuals this large beyond the measurement noise, so a
// real robot's calibration is not refused for being a real robot.
struct UnmodelledErrorSpec {
  double position = 20e-6;  // m
  double rotation = 1e-4;   // rad
  int line = 0;             // robot-file line (0: the defaults)
};

// What a G-code program's axis words mean to this robot's controller (robot file `controller:
// {gcode_axes: ...}`): the tool position (the firmware computes the robot's kinematics, e.g. a
// printer firmware's delta kinematics) or one axis per actuator (raw-axis mode: X Y Z U V W A B C
// in actuator order, millimetres or degrees; the firmware does no kinematics, as robocal's
// G-code link drives a robot).
enum class GcodeAxes : std::uint8_t { kUnknown, kTool, kActuators };

struct ControllerSpec {
  GcodeAxes gcode_axes = GcodeAxes::kUnknown;  // kUnknown: the file does not say
  int line = 0;
};

struct Mechanism {
  std::string name;
  std::string source;  // file the model was read from (for messages)
  std::string description;
  std::vector<Body> bodies;  // topologically sorted (pre-order): parent index < own index
  std::vector<Closure> closures;
  std::vector<Parameter> parameters;
  std::vector<int> actuated;  // body indices of actuated joints, in file order
  std::vector<int> passive;   // body indices of passive joints (closure / IK unknowns)
  int tool = -1;              // default frame (tool); body index
  TaskSpace task;
  ClosedFormSpec closed_form;
  WorkspaceSpec workspace;
  AssemblyModeSpec assembly_mode;
  UnmodelledErrorSpec unmodelled_error;
  ControllerSpec controller;

  int constraint_rows() const;  // sum of closure_rows over closures
  // -1 if absent.
  int body_index(const std::string& name) const;
  int parameter_index(const std::string& name) const;
  // display_name of parameter `index` (label if the robot file gives one, else the raw name).
  const std::string& parameter_display_name(std::size_t index) const;
  // Nominal parameter values in parameter order.
  Eigen::VectorXd nominal_parameters() const;
  // Home joint values of the passive joints (generic seed).
  Eigen::VectorXd home_passive() const;
  // Home joint values of the actuated joints (joint units, actuator order).
  Eigen::VectorXd home_actuated() const;
};

// Joint variable of every body (q, joint units after the encoder model; 0 for fixed bodies).
// Indexing by body keeps frame evaluation independent of which joints are actuated.
struct JointState {
  Eigen::VectorXd q;
};

// Builds the per-body joint state from actuator readings (encoder units) and passive joint
// values, applying the encoder model q = scale * reading + offset.
JointState make_joint_state(const Mechanism& model, const Eigen::VectorXd& params,
                            const Eigen::VectorXd& actuator_readings,
                            const Eigen::VectorXd& passive);

// Encoder scale of every actuator at `params` (joint units per reading unit, signed; 1 for
// readings in rad or m, 2 pi / 268000 for the wire robot's counts).
Eigen::VectorXd encoder_scales(const Mechanism& model, const Eigen::VectorXd& params);

// Inverse of the encoder model: readings for actuator joint values q (joint units).
Eigen::VectorXd readings_from_joint_values(const Mechanism& model, const Eigen::VectorXd& params,
                                           const Eigen::VectorXd& actuator_q);

}  // namespace robocal::calib
