#pragma once
// Internal: fast open-tree evaluation with parameter-dependent fixed transforms cached, exact
// joint twists, closure residual rows and their derivatives, and the damped Gauss-Newton loop
// shared by the closure solver and inverse kinematics. Not installed; not public API.
#include "robocal/calib/mechanism.hpp"
#include "small_lu.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

namespace robocal::calib::detail {

struct Rigid {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
};

inline int axis_of(OpKind k) {
  return static_cast<int>(k) % 3;
}
inline bool is_rotation(OpKind k) {
  return static_cast<int>(k) < 3;
}

// Right-multiplies an elementary transform onto (R, p).
inline void apply_op(Eigen::Matrix3d& R, Eigen::Vector3d& p, OpKind kind, double value) {
  // A zero op is the identity exactly (cos 0 = 1, sin 0 = 0): most of a model's constant ops are
  // (the MCPC twist angles of the design), and their sine and cosine were a tenth of a solve.
  if (value == 0.0) return;
  const int ax = axis_of(kind);
  if (!is_rotation(kind)) {
    p += value * R.col(ax);
    return;
  }
  const int i = (ax + 1) % 3, j = (ax + 2) % 3;
  const double c = std::cos(value), s = std::sin(value);
  const Eigen::Vector3d ci = R.col(i), cj = R.col(j);
  R.col(i) = c * ci + s * cj;
  R.col(j) = c * cj - s * ci;
}

inline double op_value(const ElementaryOp& op, const Eigen::VectorXd& params, double q) {
  return (op.param >= 0 ? params[op.param] : 0.0) + (op.joint ? op.sign * q : 0.0);
}

inline bool in_subtree(const Mechanism& m, int root, int body) {
  return body >= root && body < m.bodies[root].subtree_end;
}

// Value rows of one closure.
void closure_value(const Closure& c, const Rigid& A, const Rigid& B, double length, double* out);
// Derivative rows of one closure for frame motions (dp, w) of A and B (world frame).
void closure_derivative(const Closure& c, const Rigid& A, const Rigid& B,
                        const Eigen::Vector3d& dpA, const Eigen::Vector3d& wA,
                        const Eigen::Vector3d& dpB, const Eigen::Vector3d& wB, double* out);
// Rotation residual of pose closures / pose targets: 0.5 * sum_k b_k x a_k.
Eigen::Vector3d rotation_residual(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb);
Eigen::Vector3d rotation_residual_derivative(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb,
                                             const Eigen::Vector3d& wA, const Eigen::Vector3d& wB);

class TreeEvaluator {
 public:
  TreeEvaluator() = default;
  TreeEvaluator(const Mechanism& model, const Eigen::VectorXd& params);

  // World poses for per-body joint values q; also joint axes/origins in world.
  void update(const Eigen::VectorXd& q);
  const Rigid& pose(int body) const { return poses_[body]; }
  // Unit twist of body's joint: dp_f = w x p_f + v for descendants f.
  void joint_twist(int body, Eigen::Vector3d& w, Eigen::Vector3d& v) const;
  // Closure rows (model.constraint_rows()) at the current poses.
  void closure_residual(double* out) const;
  // d(closure rows)/dq of body's joint, times `scale`, written to `out` (constraint_rows()).
  void closure_column(int body, double scale, double* out) const;

  const Mechanism& model() const { return *model_; }
  const Eigen::VectorXd& params() const { return params_; }
  int rows() const { return rows_; }

 private:
  const Mechanism* model_ = nullptr;
  Eigen::VectorXd params_;
  std::vector<Rigid> pre_, post_;  // ops before / after the joint op
  std::vector<char> has_post_;     // post_ is not the identity (DH, Hayati; not MCPC)
  std::vector<Rigid> poses_;
  std::vector<Rigid> joint_frames_;  // world frame just before the joint op
  int rows_ = 0;
};

// Damped Gauss-Newton (Levenberg) on a system with evaluate(x, r) (residual; the system keeps
// the state) and jacobian(J) (at the last evaluated x). Square systems first try the plain
// Newton step (LU); the damped normal equations take over when it does not reduce the residual
// (far from the solution, singular poses, idle mobilities).
struct LmWorkspace {
  Eigen::MatrixXd J, A;
  Eigen::VectorXd r, g, dx, x_trial, r_trial;
  SmallCholesky chol;
  SmallLu lu;
  // The last accepted step was a plain Newton step: `lu` factors the Jacobian of the previous
  // iterate (which at convergence is the solution's to within the last step).
  bool lu_current = false;
  void resize(Eigen::Index rows, Eigen::Index cols) {
    if (J.rows() != rows || J.cols() != cols) {
      J.resize(rows, cols);
      A.resize(cols, cols);
      // lu sizes itself on its first factor() and reuses the storage afterwards.
    }
    r.resize(rows);
    r_trial.resize(rows);
    g.resize(cols);
    dx.resize(cols);
    x_trial.resize(cols);
  }
};

struct LmOutcome {
  bool converged = false;
  bool stalled = false;
  double residual = 0.0;  // max |r|
  int iterations = 0;
};

inline double max_abs(const Eigen::VectorXd& v) {
  return v.size() ? v.cwiseAbs().maxCoeff() : 0.0;
}

// sigma_min / sigma_max of J (n columns; 0 when J has fewer rows than columns or is zero), exact to
// rounding: from the eigenvalues of J^T J, which for the closure Jacobians (n ~ 15) costs a tenth
// of a Jacobi SVD. Squaring loses nothing that matters here: a ratio of 1e-2 is 1e-4 in
// eigenvalues, resolved to ~1e-12 relative; ratios under ~1e-8 come out as a tiny number or 0,
// far below every threshold either way.
inline double sigma_ratio(const Eigen::MatrixXd& J) {
  const Eigen::Index n = J.cols();
  if (n == 0 || J.rows() < n) return 0.0;
  const Eigen::MatrixXd gram = J.transpose() * J;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(gram, Eigen::EigenvaluesOnly);
  const Eigen::VectorXd& ev = eig.eigenvalues();  // ascending
  if (eig.info() != Eigen::Success || !(ev[n - 1] > 0.0)) return 0.0;
  return std::sqrt(std::max(ev[0], 0.0) / ev[n - 1]);
}

// B = J^T J and rho, a lower bound of its largest eigenvalue (four power iterations from the
// all-ones vector; a few per cent under it on these Jacobians). False where J is degenerate.
inline bool gram_and_rho(const Eigen::MatrixXd& J, Eigen::MatrixXd& B, double& rho) {
  const Eigen::Index n = J.cols();
  if (n == 0 || J.rows() < n) return false;
  gram_matrix(J, B);
  Eigen::VectorXd v = Eigen::VectorXd::Ones(n), w(n);
  rho = 0.0;
  for (int k = 0; k < 4; ++k) {
    const double norm = v.norm();
    if (!(norm > 0.0)) return false;
    v /= norm;
    w.noalias() = B * v;
    rho = v.dot(w);
    v.swap(w);
  }
  return rho > 0.0 && std::isfinite(rho);
}

// Whether sign * B + shift I is positive definite (a Cholesky factorisation exists).
inline bool shifted_positive_definite(const Eigen::MatrixXd& B, double sign, double shift) {
  if (B.rows() > SmallCholesky::kMax) {
    Eigen::MatrixXd A = sign * B;
    A.diagonal().array() += shift;
    return Eigen::LLT<Eigen::MatrixXd>(A).info() == Eigen::Success;
  }
  SmallCholesky chol;
  return chol.factor(B, sign, shift);
}

// A proved upper bound c of lambda_max(B), given rho <= lambda_max (gram_and_rho): the tightest of
// 1.02, 1.1 and 1.5 rho for which c I - B is positive definite (the power iteration is a few per
// cent at most under lambda_max, often under one). Empty when none is.
inline std::optional<double> lambda_max_bound(const Eigen::MatrixXd& B, double rho) {
  for (const double f : {1.02, 1.1, 1.5})
    if (shifted_positive_definite(B, -1.0, f * rho)) return f * rho;
  return std::nullopt;
}

// Whether sigma_min / sigma_max of J is certainly above t, without the eigenvalues, given
// c >= lambda_max(B) (lambda_max_bound): B - t^2 c I positive definite proves
// lambda_min > t^2 c >= t^2 lambda_max. With c from the 1.02 rho try the ratio is proved from
// about 1.01 t, from the 1.5 rho try from about 1.22 t. Failing answers false, and the caller
// computes the ratio exactly. A quarter of the cost of the eigenvalues, and the common answer
// away from singular configurations.
inline bool gram_ratio_certainly_above(const Eigen::MatrixXd& B, double c, double t) {
  return shifted_positive_definite(B, 1.0, -t * t * c);
}
inline bool sigma_ratio_certainly_above(const Eigen::MatrixXd& J, double t) {
  Eigen::MatrixXd B(J.cols(), J.cols());
  double rho = 0.0;
  if (!gram_and_rho(J, B, rho)) return false;
  const std::optional<double> c = lambda_max_bound(B, rho);
  return c && gram_ratio_certainly_above(B, *c, t);
}

// Bounds on the singular values of J: sigma_min >= lo and sigma_max <= hi = sqrt(c), given
// c >= lambda_max(B) (lambda_max_bound), lo proved by Cholesky (B - lo^2 I positive definite)
// around the guess `ratio` (an estimate of sigma_min / sigma_max) times sqrt(rho): 10 % under it
// first, then 40 %.
struct SingularBounds {
  double lo = 0.0;
  double hi = 0.0;
};
inline std::optional<SingularBounds> gram_singular_bounds(const Eigen::MatrixXd& B, double rho,
                                                          double c, double ratio) {
  if (!(ratio > 0.0) || !std::isfinite(ratio)) return std::nullopt;
  const double sigma_min = ratio * std::sqrt(rho);
  for (const double f : {0.9, 0.6})
    if (shifted_positive_definite(B, 1.0, -(f * sigma_min) * (f * sigma_min)))
      return SingularBounds{f * sigma_min, std::sqrt(c)};
  return std::nullopt;
}

// Estimate of sigma_min / sigma_max of a square J from its LU factors (no allocation: v and w are
// n-sized scratch vectors): sigma_max by power iteration on J^T J, sigma_min by inverse iteration
// with the factors. Two and three iterations: cheap (O(n^2) each, ~1 us on the Delta) and, for
// a threshold of 1e-2, accurate enough: sigma_max's power iteration from the all-ones vector is
// within a few per cent after two steps on these Jacobians, and the inverse iteration's estimate
// of sigma_min can only err high, by the ratio of the two smallest singular values to the 3rd
// power (the sweep in tests/support/mode_sweep.hpp checks the verdicts it leads to).
inline double sigma_ratio_estimate(const SmallLu& lu, const Eigen::MatrixXd& J, Eigen::VectorXd& v,
                                   Eigen::VectorXd& w) {
  const Eigen::Index n = J.cols();
  if (n == 0 || J.rows() != n) return 1.0;
  double big = 0.0, small = 0.0;
  v.setOnes();
  for (int k = 0; k < 2; ++k) {
    v /= v.norm();
    w.noalias() = J * v;
    big = w.norm();
    v.noalias() = J.transpose() * w;
    if (!(v.norm() > 0.0)) return 0.0;
  }
  // (J^T J)^-1 u from the LU factors (SmallLu::gram_inverse_apply: four triangular solves in
  // place). Factors that do not exist (a zero pivot): singular, the caller's exact ratio decides.
  if (!lu.ok() || lu.size() != n) return 0.0;
  v.setOnes();
  for (int k = 0; k < 3; ++k) {
    v /= v.norm();
    lu.gram_inverse_apply(v);
    const double g = std::sqrt(v.norm());  // ||(J^T J)^-1 u|| -> 1 / sigma_min^2
    if (!std::isfinite(g) || g <= 0.0) return 0.0;
    small = 1.0 / g;
  }
  return big > 0.0 ? small / big : 0.0;
}

// The same estimate from B = J^T J and rho (gram_and_rho), for a caller without LU factors of J
// who needs B for the certificate anyway: sigma_max^2 >= rho (four power iterations on B),
// sigma_min^2 by three steps of inverse iteration through B's Cholesky factor. It too can only
// overstate the ratio (rho is a Rayleigh quotient of B, and 1 / ||B^-1 u|| >= lambda_min(B) for a
// unit u). 0 where B is not positive definite (singular: the caller's exact ratio decides).
// With `shift` s > 0 the inverse iteration runs on B - s I (lambda_min(B) = lambda_min(B - s I) +
// s, and the estimate still overstates): where that matrix is positive definite its factor both
// proves lambda_min(B) > s and serves the estimate. 0 where it is not.
inline double gram_ratio_estimate(const Eigen::MatrixXd& B, double rho, Eigen::VectorXd& v,
                                  double shift = 0.0) {
  SmallCholesky chol;
  if (!(rho > 0.0) || !chol.factor(B, 1.0, -shift)) return 0.0;
  double small2 = 0.0;  // estimate of sigma_min^2 = lambda_min(B)
  v.setOnes(B.cols());
  for (int k = 0; k < 3; ++k) {
    v /= v.norm();
    chol.solve(v);
    const double g = v.norm();  // ||(B - s I)^-1 u|| -> 1 / lambda_min(B - s I)
    if (!std::isfinite(g) || g <= 0.0) return 0.0;
    small2 = 1.0 / g + shift;
  }
  return std::sqrt(small2 / rho);
}

// sigma_min / sigma_max of a square J for comparisons with the thresholds `gate` <= `upper` (`lu`:
// LU factors of J when the caller has them, else null: the estimate then comes from J^T J, which
// the certificate shares; v, w scratch). The estimate can only overstate the ratio, so it
// already places the ratio below every threshold above it; what needs proof is that the ratio
// clears the highest threshold the estimate meets. Returned: the estimate where it is at least
// `trusted_above` (it overstates by less than that margin over every threshold), or where the
// certificate proves the ratio above that threshold (the ratio then lies between the same
// thresholds as the estimate), else the exact ratio (so below `gate`, the ambiguous verdict
// reports the true distance to the singularity). Used by the closure solver and inverse
// kinematics alike. With `bounds` (the closure solver's carried bounds), singular-value bounds
// are proved along with the certificate, whose Gram matrix they share, and also for a trusted
// estimate when `bounds_when_trusted`; they replace the certificate where they clear the
// threshold.
struct GatedRatio {
  double ratio = 0.0;
  std::optional<SingularBounds> bounds;
};
inline GatedRatio gated_sigma_ratio(const SmallLu* lu, const Eigen::MatrixXd& J, Eigen::VectorXd& v,
                                    Eigen::VectorXd& w, double trusted_above, double gate,
                                    double upper, bool bounds = false,
                                    bool bounds_when_trusted = false) {
  GatedRatio out;
  if (J.cols() == 0 || J.rows() != J.cols()) {
    out.ratio = 1.0;  // as sigma_ratio_estimate: only square closures are judged
    return out;
  }
  Eigen::MatrixXd B;
  double rho = 0.0;
  int gram = -1;            // B and rho: -1 not yet computed, 0 degenerate, 1 at hand
  std::optional<double> c;  // lambda_max_bound(B, rho), once tried
  bool c_tried = false;
  bool proved_upper = false;  // the ratio is proved above `upper`
  if (lu != nullptr || J.cols() > SmallCholesky::kMax) {
    SmallLu own;
    if (lu == nullptr) {
      own.factor(J);
      lu = &own;
    }
    out.ratio = sigma_ratio_estimate(*lu, J, v, w);
  } else {
    // Without LU factors: the certificate at `upper` first, whose factor also gives the estimate
    // (gram_ratio_estimate with a shift); the plain estimate where it fails.
    gram = gram_and_rho(J, B, rho) ? 1 : 0;
    if (gram == 1) {
      c = lambda_max_bound(B, rho);
      c_tried = true;
      if (c) {
        out.ratio = gram_ratio_estimate(B, rho, v, upper * upper * *c);
        proved_upper = out.ratio > 0.0;
      }
      if (!proved_upper) out.ratio = gram_ratio_estimate(B, rho, v);
    }
  }
  const bool trusted = out.ratio >= trusted_above;
  if ((trusted || proved_upper) && !(bounds && bounds_when_trusted)) return out;
  const double met = out.ratio >= upper ? upper : gate;
  if (out.ratio >= met) {
    if (gram < 0) gram = gram_and_rho(J, B, rho) ? 1 : 0;
    if (!c_tried && gram == 1) c = lambda_max_bound(B, rho);
    if (c) {
      if (bounds) {
        out.bounds = gram_singular_bounds(B, rho, *c, out.ratio);
        if (out.bounds && out.bounds->lo >= met * out.bounds->hi) return out;
      }
      if (trusted || proved_upper || gram_ratio_certainly_above(B, *c, met)) return out;
    }
  }
  out.bounds.reset();
  out.ratio = sigma_ratio(J);
  return out;
}

// The conditioning (gated_sigma_ratio) of the answers of one solver, which along a path of warm
// solves come close to each other: singular-value bounds proved for one answer's Jacobian J0 are
// carried to the next ones by Weyl's inequality, |sigma_i(J) - sigma_i(J0)| <= ||J - J0||_F, so
// one proof keeps the ratio clear of the thresholds for many steps at the cost of a matrix
// difference (on the Delta's 1 mm helix the closure Jacobian moves by 0.12 % of sigma_max per
// step). Where the carried bounds clear every threshold, the returned conditioning is their
// proved lower bound of the ratio.
// `lu`: the LU factors of J when the caller has them, else null (gated_sigma_ratio).
class PathConditioning {
 public:
  double operator()(const SmallLu* lu, const Eigen::MatrixXd& J, Eigen::VectorXd& v,
                    Eigen::VectorXd& w, double trusted_above, double gate, double upper) {
    bool in_reach = false;
    if (J0_.rows() == J.rows() && J0_.cols() == J.cols()) {
      const double d = (J - J0_).norm();
      const double lo = at_J0_.lo - d;
      in_reach = lo > 0.0;
      if (in_reach && lo >= upper * (at_J0_.hi + d)) return lo / (at_J0_.hi + d);
    }
    // New bounds cost a certificate's worth (with the certificate, two more factorisations of
    // the same Gram matrix): paid only on a path of warm solves, where they are carried (the
    // carried bounds in reach, or this Jacobian within 1 % of the last one), not by cold solves
    // scattered over the workspace.
    const bool on_a_path = in_reach || (last_J_.rows() == J.rows() && last_J_.cols() == J.cols() &&
                                        (J - last_J_).norm() <= 0.01 * J.norm());
    last_J_ = J;
    const GatedRatio r =
        gated_sigma_ratio(lu, J, v, w, trusted_above, gate, upper, on_a_path, on_a_path);
    if (r.bounds && r.bounds->lo >= upper * r.bounds->hi) {
      J0_ = J;
      at_J0_ = *r.bounds;
    }
    return r.ratio;
  }

 private:
  Eigen::MatrixXd J0_;  // a Jacobian with proved singular-value bounds
  SingularBounds at_J0_;
  Eigen::MatrixXd last_J_;  // the last answer's
};

template <class System>
LmOutcome levenberg_marquardt(System& sys, Eigen::VectorXd& x, LmWorkspace& ws, int max_iterations,
                              double tolerance, double max_step) {
  LmOutcome out;
  const Eigen::Index n = x.size();
  const bool square = sys.rows() == n;
  ws.resize(sys.rows(), n);
  ws.lu_current = false;
  sys.evaluate(x, ws.r);
  double cost = ws.r.squaredNorm();
  double lambda = 1e-12;
  bool newton_ok = square;  // try undamped Newton until it fails once
  for (out.iterations = 0; out.iterations < max_iterations; ++out.iterations) {
    out.residual = max_abs(ws.r);
    if (!std::isfinite(out.residual)) return out;
    if (out.residual <= tolerance) {
      out.converged = true;
      return out;
    }
    if (n == 0) break;
    sys.jacobian(ws.J);
    bool accepted = false;
    bool normal_ready = false;
    double scale = 1.0;
    for (int attempt = 0; attempt < 30 && !accepted; ++attempt) {
      if (newton_ok && attempt == 0) {
        if (!ws.lu.factor(ws.J)) continue;  // singular: damped steps
        ws.dx = -ws.r;
        ws.lu.solve(ws.dx);
        if (!ws.dx.allFinite()) continue;
      } else {
        if (!normal_ready) {
          gram_matrix(ws.J, ws.A);
          ws.g.noalias() = ws.J.transpose() * ws.r;
          scale = std::max(ws.A.diagonal().maxCoeff(), 1e-300);
          normal_ready = true;
        }
        if (n <= SmallCholesky::kMax) {
          if (!ws.chol.factor(ws.A, 1.0, lambda * scale)) {
            lambda *= 100.0;
            continue;
          }
          ws.dx = -ws.g;
          ws.chol.solve(ws.dx);
        } else {
          for (Eigen::Index i = 0; i < n; ++i) ws.A(i, i) += lambda * scale;
          // Past SmallCholesky::kMax unknowns (no library closure): Eigen's, factored here (an
          // uncomputed LLT kept in the workspace would be copied uninitialised with a solver).
          const Eigen::LLT<Eigen::MatrixXd> llt(ws.A);
          for (Eigen::Index i = 0; i < n; ++i) ws.A(i, i) -= lambda * scale;
          if (llt.info() != Eigen::Success) {
            lambda *= 100.0;
            continue;
          }
          ws.dx = llt.solve(ws.g);
          ws.dx = -ws.dx;
        }
      }
      const double step = max_abs(ws.dx);
      if (step > max_step) ws.dx *= max_step / step;
      ws.x_trial = x + ws.dx;
      sys.evaluate(ws.x_trial, ws.r_trial);
      const double trial_cost = ws.r_trial.squaredNorm();
      if (std::isfinite(trial_cost) && (trial_cost < cost || max_abs(ws.r_trial) <= tolerance)) {
        accepted = true;
        ws.lu_current = newton_ok && attempt == 0;
        x.swap(ws.x_trial);
        ws.r.swap(ws.r_trial);
        cost = trial_cost;
        if (!(newton_ok && attempt == 0)) lambda = std::max(lambda * 0.1, 1e-15);
      } else {
        if (newton_ok && attempt == 0) {
          newton_ok = false;  // far from the solution: damped steps from now on
          continue;
        }
        if (step <= 1e-15 * (1.0 + max_abs(x))) break;
        lambda *= 10.0;
      }
    }
    if (!accepted) {
      out.stalled = true;
      // Leave the system evaluated at the returned x.
      sys.evaluate(x, ws.r);
      break;
    }
  }
  out.residual = max_abs(ws.r);
  out.converged = out.residual <= tolerance;
  return out;
}

// Task-space residual rows of an IK target (position 3, pose 6, joint 1).
inline int task_rows(TaskType t) {
  switch (t) {
    case TaskType::kPosition:
      return 3;
    case TaskType::kPose:
      return 6;
    case TaskType::kJoint:
      return 1;
  }
  return 0;
}

}  // namespace robocal::calib::detail
