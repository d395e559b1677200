#include "fit/corner_noise.hpp"

#include <Eigen/Cholesky>

#include <map>
#include <utility>

namespace robocal::vision::detail {

WhitenedGroupCost::WhitenedGroupCost(std::vector<std::unique_ptr<ceres::CostFunction>> corners,
                                     Eigen::MatrixXd whitening)
    : corners_(std::move(corners)), whitening_(std::move(whitening)) {
  *mutable_parameter_block_sizes() = corners_.front()->parameter_block_sizes();
  set_num_residuals(2 * static_cast<int>(corners_.size()));
}

bool WhitenedGroupCost::Evaluate(double const* const* parameters, double* residuals,
                                 double** jacobians) const {
  const auto& sizes = parameter_block_sizes();
  const Eigen::Index n = num_residuals();
  Eigen::VectorXd r(n);
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  std::vector<RowMajor> jac;
  if (jacobians != nullptr) {
    for (int s : sizes) jac.emplace_back(n, s);
  }
  for (size_t k = 0; k < corners_.size(); ++k) {
    double rk[2];
    std::vector<Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>> jk;
    std::vector<double*> jk_ptr;
    if (jacobians != nullptr) {
      for (size_t b = 0; b < sizes.size(); ++b) {
        jk.emplace_back(2, sizes[b]);
        jk_ptr.push_back(jacobians[b] != nullptr ? jk.back().data() : nullptr);
      }
    }
    if (!corners_[k]->Evaluate(parameters, rk, jacobians != nullptr ? jk_ptr.data() : nullptr))
      return false;
    r.segment<2>(static_cast<Eigen::Index>(2 * k)) = Eigen::Vector2d(rk[0], rk[1]);
    if (jacobians != nullptr) {
      for (size_t b = 0; b < sizes.size(); ++b)
        if (jacobians[b] != nullptr) jac[b].middleRows<2>(static_cast<Eigen::Index>(2 * k)) = jk[b];
    }
  }
  Eigen::Map<Eigen::VectorXd>(residuals, n) = whitening_ * r;
  if (jacobians != nullptr) {
    for (size_t b = 0; b < sizes.size(); ++b) {
      if (jacobians[b] == nullptr) continue;
      Eigen::Map<RowMajor>(jacobians[b], n, sizes[b]) = whitening_ * jac[b];
    }
  }
  return true;
}

CornerGrouping group_corners(const std::vector<int>& ids, const std::vector<bool>& use,
                             const std::vector<CornerGroup>& groups) {
  CornerGrouping out;
  std::map<int, size_t> index;
  for (size_t i = 0; i < ids.size(); ++i)
    if (use[i]) index[ids[i]] = i;
  std::vector<bool> grouped(ids.size(), false);
  for (const CornerGroup& g : groups) {
    const auto n = static_cast<Eigen::Index>(g.corner_ids.size());
    if (g.covariance.rows() != 2 * n || g.covariance.cols() != 2 * n) continue;
    std::vector<size_t> members;
    std::vector<Eigen::Index> rows;
    for (Eigen::Index k = 0; k < n; ++k) {
      const auto it = index.find(g.corner_ids[static_cast<size_t>(k)]);
      if (it == index.end() || grouped[it->second]) continue;
      members.push_back(it->second);
      rows.push_back(2 * k);
      rows.push_back(2 * k + 1);
    }
    if (members.empty()) continue;
    Eigen::MatrixXd sub(rows.size(), rows.size());
    for (size_t a = 0; a < rows.size(); ++a)
      for (size_t b = 0; b < rows.size(); ++b)
        sub(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(b)) =
            g.covariance(rows[a], rows[b]);
    const Eigen::LLT<Eigen::MatrixXd> llt(sub);
    if (llt.info() != Eigen::Success || !sub.allFinite()) continue;  // unusable: independent
    const Eigen::MatrixXd l = llt.matrixL();
    // A near-singular covariance would give a huge weight to one combination of corners.
    if (l.diagonal().minCoeff() < 1e-4 * l.diagonal().maxCoeff()) continue;
    out.whitening.emplace_back(
        l.triangularView<Eigen::Lower>().solve(Eigen::MatrixXd::Identity(sub.rows(), sub.cols())));
    for (size_t m : members) grouped[m] = true;
    out.groups.push_back(std::move(members));
  }
  for (size_t i = 0; i < ids.size(); ++i)
    if (use[i] && !grouped[i]) out.singles.push_back(i);
  return out;
}

}  // namespace robocal::vision::detail
