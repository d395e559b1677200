// Observability-driven pose selection (see selection.hpp).
#include "robocal/planner/selection.hpp"

#include "robocal/calib/identifiability.hpp"
#include "robocal/calib/mechanism_predictor.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>

namespace robocal::planner {

const char* to_string(ObservabilityIndex index) {
  switch (index) {
    case ObservabilityIndex::kO1:
      return "O1";
    case ObservabilityIndex::kO2:
      return "O2";
    case ObservabilityIndex::kO3:
      return "O3";
    case ObservabilityIndex::kO4:
      return "O4";
    case ObservabilityIndex::kO5:
      return "O5";
    case ObservabilityIndex::kTask:
      return "task";
  }
  return "?";
}

bool parse_index(const std::string& text, ObservabilityIndex* index) {
  std::string t;
  for (const char c : text)
    t.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  if (t == "o1" || t == "d-optimal")
    *index = ObservabilityIndex::kO1;
  else if (t == "o2")
    *index = ObservabilityIndex::kO2;
  else if (t == "o3")
    *index = ObservabilityIndex::kO3;
  else if (t == "o4")
    *index = ObservabilityIndex::kO4;
  else if (t == "o5")
    *index = ObservabilityIndex::kO5;
  else if (t == "task" || t == "i-optimal")
    *index = ObservabilityIndex::kTask;
  else
    return false;
  return true;
}

namespace {

using Mat6 = Eigen::Matrix<double, 6, 6>;
using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Whitened 6 x P Jacobian of one pose (zero when the pose cannot be solved).
Eigen::Matrix<double, 6, Eigen::Dynamic> whitened_jacobian(
    const calib::MechanismPredictor& predictor, const Eigen::VectorXd& params,
    const Eigen::VectorXd& readings, int slot, const ObservabilityOptions& o) {
  calib::FramePrediction out;
  std::string why;
  const auto P = static_cast<Eigen::Index>(predictor.parameter_count());
  if (!predictor.predict(params, readings, slot, true, out, why))
    return Eigen::Matrix<double, 6, Eigen::Dynamic>::Zero(6, P);
  Eigen::Matrix<double, 6, Eigen::Dynamic> J = out.jacobian;
  J.topRows<3>() /= o.position_sigma;
  J.bottomRows<3>() /= o.rotation_sigma;
  return J;
}

// Singular values (descending) of the scaled Jacobian of a set, from its normal matrix.
Eigen::VectorXd singular_values_of(const Eigen::MatrixXd& normal) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(normal, Eigen::EigenvaluesOnly);
  Eigen::VectorXd ev = es.eigenvalues().cwiseMax(0.0).cwiseSqrt();
  std::reverse(ev.data(), ev.data() + ev.size());
  return ev;
}

std::array<double, 5> indices_from(const Eigen::VectorXd& s, std::size_t m) {
  std::array<double, 5> o{};
  const auto L = s.size();
  if (L == 0 || m == 0) return o;
  const double s1 = s(0), sl = s(L - 1);
  double log_sum = 0.0, inv_sum = 0.0;
  for (Eigen::Index i = 0; i < L; ++i) {
    log_sum += std::log(std::max(s(i), 1e-300));
    inv_sum += 1.0 / std::max(s(i), 1e-300);
  }
  o[0] = std::exp(log_sum / static_cast<double>(L)) / std::sqrt(static_cast<double>(m));
  o[1] = s1 > 0 ? sl / s1 : 0.0;
  o[2] = sl;
  o[3] = s1 > 0 ? sl * sl / s1 : 0.0;
  o[4] = 1.0 / inv_sum;
  return o;
}

double logdet_spd(const Mat6& A) {
  Eigen::LLT<Mat6> llt(A);
  if (llt.info() != Eigen::Success) return -std::numeric_limits<double>::infinity();
  const Mat6 L = llt.matrixL();
  return 2.0 * L.diagonal().array().log().sum();
}

// Greedy/exchange state: the inverse information matrix (with a small prior so it exists from
// the first pose) and S_i = J_i M^-1 J_i^T for every pool pose, kept current by rank-6 updates.
class DesignState {
 public:
  DesignState(const ObservabilityModel& model, double prior) : J_(model.rows), prior_(prior) {
    n_ = model.poses();
    L_ = static_cast<Eigen::Index>(model.columns());
    in_.assign(n_, false);
    normal_ = Eigen::MatrixXd::Zero(L_, L_);
    refresh();
  }
  void add(std::size_t k) { update(k, +1.0); }
  void remove(std::size_t k) { update(k, -1.0); }
  // Recomputes M^-1 and S exactly (bounds the round-off of many updates).
  void refresh() {
    Eigen::MatrixXd M = normal_;
    M.diagonal().array() += prior_;
    Minv_ = M.llt().solve(Eigen::MatrixXd::Identity(L_, L_));
    const RowMat JM = J_ * Minv_;
    S_.resize(static_cast<Eigen::Index>(6 * n_), 6);
    for (std::size_t i = 0; i < n_; ++i) {
      const auto r = static_cast<Eigen::Index>(6 * i);
      S_.middleRows<6>(r) = JM.middleRows<6>(r) * J_.middleRows<6>(r).transpose();
    }
  }
  double gain(std::size_t i) const {
    return logdet_spd(Mat6::Identity() + S_.middleRows<6>(static_cast<Eigen::Index>(6 * i)));
  }
  double loss(std::size_t i) const {  // log det decrease when removing a member (>= 0)
    return -logdet_spd(Mat6::Identity() - S_.middleRows<6>(static_cast<Eigen::Index>(6 * i)));
  }
  bool in(std::size_t i) const { return in_[i]; }
  const Eigen::MatrixXd& normal() const { return normal_; }
  const Eigen::MatrixXd& inverse() const { return Minv_; }
  const Mat6 S(std::size_t i) const { return S_.middleRows<6>(static_cast<Eigen::Index>(6 * i)); }
  // Predicted 1-σ position variance (scaled-whitened units: × σ_p² for m²) at pose i.
  double position_variance(std::size_t i) const {
    return S_.block<3, 3>(static_cast<Eigen::Index>(6 * i), 0).trace();
  }
  std::size_t size() const { return n_; }

 private:
  void update(std::size_t k, double sign) {
    const auto r = static_cast<Eigen::Index>(6 * k);
    const Eigen::Matrix<double, Eigen::Dynamic, 6> U = Minv_ * J_.middleRows<6>(r).transpose();
    const Mat6 C = Mat6::Identity() + sign * (J_.middleRows<6>(r) * U);
    const Mat6 Cinv = C.inverse();
    Minv_.noalias() -= sign * (U * Cinv * U.transpose());
    const Eigen::Matrix<double, Eigen::Dynamic, 6> B = J_ * U;  // 6n x 6
    for (std::size_t i = 0; i < n_; ++i) {
      const auto ri = static_cast<Eigen::Index>(6 * i);
      S_.middleRows<6>(ri).noalias() -=
          sign * (B.middleRows<6>(ri) * Cinv * B.middleRows<6>(ri).transpose());
    }
    normal_.noalias() += sign * (J_.middleRows<6>(r).transpose() * J_.middleRows<6>(r));
    in_[k] = sign > 0;
  }

  const RowMat& J_;
  double prior_;
  std::size_t n_ = 0;
  Eigen::Index L_ = 0;
  std::vector<bool> in_;
  Eigen::MatrixXd normal_;
  Eigen::MatrixXd Minv_;
  RowMat S_;
};

double index_value(const Eigen::MatrixXd& normal, std::size_t m, ObservabilityIndex index) {
  return indices_from(singular_values_of(normal), m)[static_cast<std::size_t>(index)];
}

Eigen::MatrixXd with_pose(const ObservabilityModel& model, const Eigen::MatrixXd& normal,
                          std::size_t i, double sign) {
  const auto r = static_cast<Eigen::Index>(6 * i);
  return normal + sign * (model.rows.middleRows<6>(r).transpose() * model.rows.middleRows<6>(r));
}

// Outsiders sorted by D-optimal gain, best first (at most `k`).
std::vector<std::size_t> best_outsiders(const DesignState& st, std::size_t k) {
  std::vector<std::pair<double, std::size_t>> g;
  for (std::size_t i = 0; i < st.size(); ++i)
    if (!st.in(i)) g.emplace_back(st.gain(i), i);
  k = std::min(k, g.size());
  std::partial_sort(g.begin(), g.begin() + static_cast<std::ptrdiff_t>(k), g.end(),
                    [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<std::size_t> out;
  for (std::size_t j = 0; j < k; ++j) out.push_back(g[j].second);
  return out;
}

// Mean position information of the pool, W = (1/n) sum_i Jp_i^T Jp_i (scaled columns): the
// task criterion tr(W M^-1) is n^-1 sum_i tr(Jp_i M^-1 Jp_i^T), the mean predicted position
// variance over the pool.
Eigen::MatrixXd position_information(const ObservabilityModel& model) {
  const std::size_t n = model.poses();
  const auto L = static_cast<Eigen::Index>(model.columns());
  Eigen::MatrixXd W = Eigen::MatrixXd::Zero(L, L);
  for (std::size_t i = 0; i < n; ++i) {
    const auto Jp = model.rows.middleRows<3>(static_cast<Eigen::Index>(6 * i));
    W.noalias() += Jp.transpose() * Jp;
  }
  return W / static_cast<double>(std::max<std::size_t>(n, 1));
}

// Change of tr(W M^-1) when pose i joins (sign +1: the decrease, >= 0) or leaves (sign -1: the
// increase, >= 0) the design, for every pose: with U = M^-1 J_i^T and C = I + sign J_i M^-1
// J_i^T, M'^-1 = M^-1 - sign U C^-1 U^T, so the change is tr(C^-1 U^T W U).
std::vector<double> task_changes(const ObservabilityModel& model, const DesignState& st,
                                 const Eigen::MatrixXd& W, double sign) {
  const std::size_t n = model.poses();
  const Eigen::MatrixXd& Minv = st.inverse();
  const Eigen::MatrixXd G = Minv * W * Minv;
  const RowMat JG = model.rows * G;
  std::vector<double> out(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    if ((sign > 0) == st.in(i)) continue;  // joining: outsiders; leaving: members
    const auto r = static_cast<Eigen::Index>(6 * i);
    const Mat6 T = JG.middleRows<6>(r) * model.rows.middleRows<6>(r).transpose();
    const Mat6 C = Mat6::Identity() + sign * st.S(i);
    out[i] = C.ldlt().solve(T).trace();
  }
  return out;
}

// An exchange of the selection's poses (DETMAX) for the task index: the outsider that lowers
// the predicted position variance most in, the member whose removal costs least out, until the
// newcomer is the least useful. Never removes the already-measured poses.
void exchange_for_task(const ObservabilityModel& model, DesignState& st, const Eigen::MatrixXd& W,
                       int limit, const std::vector<std::size_t>& measured, Selection& sel) {
  const std::size_t n = model.poses();
  auto removable = [&](std::size_t i) {
    return std::find(measured.begin(), measured.end(), i) == measured.end();
  };
  for (int it = 0; it < limit; ++it) {
    const std::vector<double> gain = task_changes(model, st, W, +1.0);
    std::size_t add = n;
    double best = -std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < n; ++i)
      if (!st.in(i) && gain[i] > best) {
        best = gain[i];
        add = i;
      }
    if (add >= n) break;
    st.add(add);
    const std::vector<double> cost = task_changes(model, st, W, -1.0);
    std::size_t drop = add;
    double least = cost[add];
    for (const std::size_t i : sel.chosen)
      if (removable(i) && cost[i] < least - 1e-12 * std::abs(least)) {
        least = cost[i];
        drop = i;
      }
    st.remove(drop);
    if (drop == add) break;  // the newcomer is the least useful: converged
    std::replace(sel.chosen.begin(), sel.chosen.end(), drop, add);
    ++sel.exchanges;
    if (sel.exchanges % 20 == 0) st.refresh();
  }
}

// The same exchange for D-optimality: the outsider of largest gain in, the member of least loss
// out.
void exchange_d_optimal(DesignState& st, int limit, const std::vector<std::size_t>& measured,
                        Selection& sel) {
  auto removable = [&](std::size_t i) {
    return std::find(measured.begin(), measured.end(), i) == measured.end();
  };
  for (int it = 0; it < limit; ++it) {
    const std::vector<std::size_t> top = best_outsiders(st, 1);
    if (top.empty()) break;
    const std::size_t add = top[0];
    st.add(add);
    std::size_t drop = add;
    double least = std::numeric_limits<double>::infinity();
    for (const std::size_t i : sel.chosen) {
      if (!removable(i)) continue;
      const double l = st.loss(i);
      if (l < least) {
        least = l;
        drop = i;
      }
    }
    if (st.loss(add) <= least + 1e-12) {  // the newcomer is the least useful: converged
      st.remove(add);
      break;
    }
    st.remove(drop);
    std::replace(sel.chosen.begin(), sel.chosen.end(), drop, add);
    ++sel.exchanges;
    if (sel.exchanges % 20 == 0) st.refresh();
  }
}

}  // namespace

ObservabilityModel build_observability_model(const calib::MechanismPredictor& predictor,
                                             const Eigen::VectorXd& params,
                                             const std::vector<Eigen::VectorXd>& pool,
                                             const ObservabilityOptions& options) {
  ObservabilityModel m;
  m.position_sigma = options.position_sigma;
  m.rotation_sigma = options.rotation_sigma;
  const calib::SolveOptions defaults = calib::solve_options_from_model(predictor.model(), false);
  std::vector<std::size_t> candidates = defaults.candidates;
  if (candidates.empty()) {
    candidates.resize(predictor.parameter_count());
    std::iota(candidates.begin(), candidates.end(), 0);
  }
  const std::vector<std::string> all_names = predictor.parameter_names();
  const std::size_t n = pool.size();
  const auto C = static_cast<Eigen::Index>(candidates.size());
  Eigen::MatrixXd full(static_cast<Eigen::Index>(6 * n), C);
  for (std::size_t i = 0; i < n; ++i) {
    const auto J = whitened_jacobian(predictor, params, pool[i], static_cast<int>(i), options);
    for (Eigen::Index c = 0; c < C; ++c)
      full.block<6, 1>(static_cast<Eigen::Index>(6 * i), c) =
          J.col(static_cast<Eigen::Index>(candidates[static_cast<std::size_t>(c)]));
  }
  // Base set over an evenly spread subsample of the pool.
  const std::size_t sub = std::min(n, options.identifiability_poses);
  Eigen::MatrixXd Jsub(static_cast<Eigen::Index>(6 * sub), C);
  for (std::size_t k = 0; k < sub; ++k) {
    const std::size_t i = k * n / std::max<std::size_t>(sub, 1);
    Jsub.middleRows<6>(static_cast<Eigen::Index>(6 * k)) =
        full.middleRows<6>(static_cast<Eigen::Index>(6 * i));
  }
  std::vector<std::string> names;
  std::vector<int> preference;
  for (const std::size_t c : candidates) {
    names.push_back(all_names[c]);
    if (!defaults.preference.empty()) preference.push_back(defaults.preference[c]);
  }
  const calib::IdentifiabilityReport rep =
      calib::analyze_identifiability(Jsub, names, calib::IdentifiabilityOptions{}, preference);
  if (rep.identifiable.empty())
    throw std::invalid_argument(
        "no parameter of the robot is identifiable from pose measurements over the candidate pool");
  m.messages = rep.messages;
  const auto L = static_cast<Eigen::Index>(rep.identifiable.size());
  m.rows.resize(static_cast<Eigen::Index>(6 * n), L);
  m.column_scale.resize(L);
  for (Eigen::Index k = 0; k < L; ++k) {
    const std::size_t c = rep.identifiable[static_cast<std::size_t>(k)];
    m.names.push_back(names[c]);
    m.parameters.push_back(candidates[c]);
    const Eigen::VectorXd col = full.col(static_cast<Eigen::Index>(c));
    const double scale =
        std::sqrt(col.squaredNorm() / static_cast<double>(std::max<std::size_t>(n, 1)));
    m.column_scale(k) = scale > 0 ? scale : 1.0;
    m.rows.col(k) = col / m.column_scale(k);
  }
  return m;
}

IndexValues evaluate_set(const ObservabilityModel& model, const std::vector<std::size_t>& set) {
  IndexValues v;
  const auto L = static_cast<Eigen::Index>(model.columns());
  Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(L, L);
  for (const std::size_t i : set) normal = with_pose(model, normal, i, 1.0);
  const Eigen::VectorXd s = singular_values_of(normal);
  v.o = indices_from(s, set.size());
  // Condition number with columns normalised over the selected set (as identifiability does).
  Eigen::VectorXd norms = normal.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (Eigen::Index k = 0; k < L; ++k)
    if (norms(k) <= 0) norms(k) = 1.0;
  const Eigen::MatrixXd scaled =
      norms.cwiseInverse().asDiagonal() * normal * norms.cwiseInverse().asDiagonal();
  const Eigen::VectorXd ss = singular_values_of(scaled);
  v.rank = 0;
  for (Eigen::Index k = 0; k < ss.size(); ++k)
    if (ss(k) > 1e-7 * ss(0)) ++v.rank;
  v.condition_number =
      ss(ss.size() - 1) > 0 ? ss(0) / ss(ss.size() - 1) : std::numeric_limits<double>::infinity();
  if (v.rank < static_cast<std::size_t>(L))
    v.condition_number = std::numeric_limits<double>::infinity();
  return v;
}

void predicted_accuracy(const ObservabilityModel& model, const std::vector<std::size_t>& set,
                        double* rms, double* max) {
  DesignState st(model, 1e-9);
  for (const std::size_t i : set) st.add(i);
  st.refresh();
  double sum = 0.0, worst = 0.0;
  for (std::size_t i = 0; i < st.size(); ++i) {
    const double var = st.position_variance(i) * model.position_sigma * model.position_sigma;
    sum += var;
    worst = std::max(worst, var);
  }
  *rms = std::sqrt(sum / static_cast<double>(std::max<std::size_t>(st.size(), 1)));
  *max = std::sqrt(worst);
}

Selection select_poses(const ObservabilityModel& model, const SelectionOptions& options,
                       const std::vector<std::size_t>& measured) {
  Selection sel;
  const std::size_t n = model.poses();
  const double prior = 1e-3;  // in units of one pose's scaled information (columns RMS 1)
  DesignState st(model, prior);
  for (const std::size_t i : measured) st.add(i);
  const std::size_t available = n - measured.size();
  const std::size_t want = std::min(options.count, available);
  const auto L = static_cast<std::size_t>(model.columns());
  const double sp2 = model.position_sigma * model.position_sigma;
  auto rms_now = [&]() {
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) sum += st.position_variance(i) * sp2;
    return std::sqrt(sum / static_cast<double>(std::max<std::size_t>(n, 1)));
  };
  std::vector<std::size_t> members = measured;
  const bool d_opt = options.index == ObservabilityIndex::kO1;
  const bool task = options.index == ObservabilityIndex::kTask;
  const Eigen::MatrixXd W = task ? position_information(model) : Eigen::MatrixXd();
  // Greedy.
  for (std::size_t step = 0; step < want; ++step) {
    std::size_t pick = n;
    if (task && 6 * members.size() >= L) {
      const std::vector<double> gain = task_changes(model, st, W, +1.0);
      double best = -std::numeric_limits<double>::infinity();
      for (std::size_t i = 0; i < n; ++i)
        if (!st.in(i) && gain[i] > best) {
          best = gain[i];
          pick = i;
        }
    } else if (d_opt || task || 6 * members.size() < L) {
      double best = -std::numeric_limits<double>::infinity();
      for (std::size_t i = 0; i < n; ++i) {
        if (st.in(i)) continue;
        const double g = st.gain(i);
        if (g > best) {
          best = g;
          pick = i;
        }
      }
    } else {
      double best = -1.0;
      for (const std::size_t i : best_outsiders(st, options.shortlist)) {
        const double v =
            index_value(with_pose(model, st.normal(), i, 1.0), members.size() + 1, options.index);
        if (v > best) {
          best = v;
          pick = i;
        }
      }
    }
    if (pick >= n) break;
    st.add(pick);
    members.push_back(pick);
    sel.chosen.push_back(pick);
    if (options.target_accuracy > 0 && 6 * members.size() >= L &&
        rms_now() <= options.target_accuracy) {
      sel.stopped_early = sel.chosen.size() < want;
      break;
    }
  }
  st.refresh();
  // Exchange (DETMAX): never removes the already-measured poses.
  if (options.exchange && !sel.stopped_early && !sel.chosen.empty()) {
    const int limit =
        options.max_exchanges > 0 ? options.max_exchanges : static_cast<int>(4 * want);
    auto removable = [&](std::size_t i) {
      return std::find(measured.begin(), measured.end(), i) == measured.end();
    };
    if (task) {
      exchange_for_task(model, st, W, limit, measured, sel);
    } else if (d_opt) {
      exchange_d_optimal(st, limit, measured, sel);
    } else {
      const std::vector<std::size_t>& all = members;
      double current = index_value(st.normal(), all.size(), options.index);
      for (int it = 0; it < limit; ++it) {
        // Members whose removal costs least information, outsiders that add most.
        std::vector<std::pair<double, std::size_t>> losses;
        for (const std::size_t i : sel.chosen)
          if (removable(i)) losses.emplace_back(st.loss(i), i);
        std::sort(losses.begin(), losses.end());
        const std::size_t kr =
            std::min<std::size_t>(losses.size(), std::max<std::size_t>(3, options.shortlist / 3));
        double best = current;
        std::size_t best_add = n, best_drop = n;
        for (const std::size_t a : best_outsiders(st, options.shortlist)) {
          const Eigen::MatrixXd plus = with_pose(model, st.normal(), a, 1.0);
          for (std::size_t r = 0; r < kr; ++r) {
            const double v = index_value(with_pose(model, plus, losses[r].second, -1.0), all.size(),
                                         options.index);
            if (v > best * (1 + 1e-9)) {
              best = v;
              best_add = a;
              best_drop = losses[r].second;
            }
          }
        }
        if (best_add >= n) break;
        st.add(best_add);
        st.remove(best_drop);
        std::replace(sel.chosen.begin(), sel.chosen.end(), best_drop, best_add);
        current = best;
        ++sel.exchanges;
        if (sel.exchanges % 20 == 0) st.refresh();
      }
    }
    st.refresh();
  }
  std::vector<std::size_t> full_set = measured;
  full_set.insert(full_set.end(), sel.chosen.begin(), sel.chosen.end());
  sel.values = evaluate_set(model, full_set);
  predicted_accuracy(model, full_set, &sel.predicted_rms, &sel.predicted_max);
  sel.accepted = sel.values.condition_number <= options.max_condition;
  std::ostringstream msg;
  msg << full_set.size() << " poses (" << sel.chosen.size() << " new) by "
      << to_string(options.index) << ", " << sel.exchanges << " exchanges; condition number "
      << sel.values.condition_number << (sel.accepted ? " <= " : " > ") << options.max_condition
      << (sel.accepted ? " (accepted)"
                       : " (REJECTED: the set cannot separate every identifiable parameter well)")
      << "; predicted position error " << sel.predicted_rms * 1e6 << " µm RMS, "
      << sel.predicted_max * 1e6 << " µm max over the working volume";
  if (sel.values.rank < L)
    msg << "; rank " << sel.values.rank << " of " << L << " identifiable parameters";
  sel.message = msg.str();
  return sel;
}

}  // namespace robocal::planner
