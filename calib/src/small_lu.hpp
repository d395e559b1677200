#pragma once
// Internal: small dense factorisations (n ~ 3-20: the closure and inverse-kinematics Newton and
// damped steps, the closure conditioning): LU with partial pivoting, Cholesky, and J^T J. At
// these sizes Eigen's blocked factorisations and general product spend most of their time in
// blocking, packing, dispatch and allocation; these plain loops over column-major storage take
// about half as long (bench_kinematics).
#include <Eigen/Core>

#include <array>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

namespace robocal::calib::detail {

class SmallLu {
 public:
  // P A = L U (L unit lower, U upper, both in one matrix). False when a pivot is zero or not
  // finite (singular or non-finite matrix: the caller falls back); the factors are then unusable.
  template <class Matrix>
  bool factor(const Matrix& a) {
    ok_ = false;
    transposed_ready_ = false;
    lu_ = a;
    const int n = static_cast<int>(lu_.rows());
    pivots_.resize(static_cast<std::size_t>(n));
    double* m = lu_.data();
    for (int k = 0; k < n; ++k) {
      double* __restrict col_k = m + static_cast<std::ptrdiff_t>(k) * n;
      int p = k;
      double best = std::abs(col_k[k]);
      for (int i = k + 1; i < n; ++i)
        if (const double v = std::abs(col_k[i]); v > best) {
          best = v;
          p = i;
        }
      if (!(best > 0.0) || !std::isfinite(best)) return false;
      pivots_[static_cast<std::size_t>(k)] = p;
      if (p != k)
        for (int j = 0; j < n; ++j)
          std::swap(m[k + static_cast<std::ptrdiff_t>(j) * n],
                    m[p + static_cast<std::ptrdiff_t>(j) * n]);
      const double inv = 1.0 / col_k[k];
      for (int i = k + 1; i < n; ++i) col_k[i] *= inv;
      for (int j = k + 1; j < n; ++j) {
        double* __restrict col_j = m + static_cast<std::ptrdiff_t>(j) * n;
        const double f = col_j[k];
        if (f == 0.0) continue;
        for (int i = k + 1; i < n; ++i) col_j[i] -= col_k[i] * f;
      }
    }
    // Reciprocals of U's diagonal: the back substitutions multiply (a division's latency, on the
    // critical path of every column, was most of their time).
    inv_diag_.resize(n);
    for (int k = 0; k < n; ++k) inv_diag_[k] = 1.0 / m[k + static_cast<std::ptrdiff_t>(k) * n];
    ok_ = true;
    return true;
  }

  // The last factor() succeeded.
  bool ok() const { return ok_; }

  // b <- A^-1 b with the last factors.
  void solve(Eigen::VectorXd& b) const {
    const int n = size();
    double* __restrict v = b.data();
    for (int k = 0; k < n; ++k) {
      const int p = pivots_[static_cast<std::size_t>(k)];
      if (p != k) std::swap(v[k], v[p]);
    }
    lower_solve(v);
    upper_solve(v);
  }

  // v <- (A^T A)^-1 v. With P A = L U, A^T A = U^T L^T L U: the permutation cancels and four
  // triangular solves remain (the inverse iteration of the closure conditioning's estimate).
  void gram_inverse_apply(Eigen::VectorXd& b) const {
    double* __restrict v = b.data();
    upper_transpose_solve(v);
    lower_transpose_solve(v);
    lower_solve(v);
    upper_solve(v);
  }

  int size() const { return static_cast<int>(lu_.rows()); }

 private:
  // v <- L^-1 v (L unit lower).
  void lower_solve(double* __restrict v) const {
    const int n = size();
    const double* m = lu_.data();
    for (int j = 0; j < n; ++j) {
      const double f = v[j];
      if (f == 0.0) continue;
      const double* col = m + static_cast<std::ptrdiff_t>(j) * n;
      for (int i = j + 1; i < n; ++i) v[i] -= col[i] * f;
    }
  }
  // v <- U^-1 v.
  void upper_solve(double* __restrict v) const {
    const int n = size();
    const double* m = lu_.data();
    for (int j = n - 1; j >= 0; --j) {
      const double* col = m + static_cast<std::ptrdiff_t>(j) * n;
      const double f = v[j] *= inv_diag_[j];
      for (int i = 0; i < j; ++i) v[i] -= col[i] * f;
    }
  }
  // v <- U^-T v. U^T is lower, and its columns are the rows of U: the columns of the transposed
  // copy, so this runs as contiguous column updates like the solves above (as a row-times-vector
  // loop it was one dependent chain of additions, several times slower).
  void upper_transpose_solve(double* __restrict v) const {
    const int n = size();
    const double* t = transposed().data();
    for (int j = 0; j < n; ++j) {
      const double* col = t + static_cast<std::ptrdiff_t>(j) * n;  // row j of U
      const double f = v[j] *= inv_diag_[j];
      for (int i = j + 1; i < n; ++i) v[i] -= col[i] * f;
    }
  }
  // v <- L^-T v (L^T unit upper; its columns are the rows of L).
  void lower_transpose_solve(double* __restrict v) const {
    const int n = size();
    const double* t = transposed().data();
    for (int j = n - 1; j >= 0; --j) {
      const double* col = t + static_cast<std::ptrdiff_t>(j) * n;  // row j of L
      const double f = v[j];
      if (f == 0.0) continue;
      for (int i = 0; i < j; ++i) v[i] -= col[i] * f;
    }
  }
  // The factors transposed, made on the first transposed solve after factor().
  const Eigen::MatrixXd& transposed() const {
    if (!transposed_ready_) {
      transposed_ = lu_.transpose();
      transposed_ready_ = true;
    }
    return transposed_;
  }

  Eigen::MatrixXd lu_;
  Eigen::VectorXd inv_diag_;
  std::vector<int> pivots_;
  bool ok_ = false;
  mutable Eigen::MatrixXd transposed_;
  mutable bool transposed_ready_ = false;
};

// B = J^T J (columns dots, the lower triangle mirrored, up to 32 columns; Eigen's product past).
inline void gram_matrix(const Eigen::MatrixXd& J, Eigen::MatrixXd& B) {
  const Eigen::Index n = J.cols();
  if (n > 32) {
    B.noalias() = J.transpose() * J;
    return;
  }
  B.resize(n, n);
  for (Eigen::Index j = 0; j < n; ++j)
    for (Eigen::Index i = j; i < n; ++i) B(j, i) = B(i, j) = J.col(i).dot(J.col(j));
}

// Cholesky factor L of sign * B + shift I (B symmetric, up to kMax columns: every closure of the
// library; the Delta's has 15) in fixed storage with plain column updates: Eigen's LLT spent more
// time allocating and dispatching than factoring at these sizes, and a verdict factors two to
// four such matrices.
class SmallCholesky {
 public:
  static constexpr Eigen::Index kMax = 32;
  // False when the matrix is not positive definite (or too large: n > kMax).
  bool factor(const Eigen::MatrixXd& B, double sign, double shift) {
    const Eigen::Index n = B.rows();
    if (n > kMax || B.cols() != n) return false;
    n_ = n;
    // Right-looking, on raw columns (restrict: the compiler may vectorise the column updates):
    // column k is scaled by its pivot's root, then the trailing lower triangle loses its outer
    // product (only the lower triangle is read).
    for (Eigen::Index j = 0; j < n; ++j)
      for (Eigen::Index i = j; i < n; ++i)
        l_[static_cast<std::size_t>(j * kMax + i)] = sign * B(i, j);
    for (Eigen::Index k = 0; k < n; ++k) l_[static_cast<std::size_t>(k * kMax + k)] += shift;
    for (Eigen::Index k = 0; k < n; ++k) {
      double* __restrict col_k = l() + k * kMax;
      const double d = col_k[k];
      if (!(d > 0.0) || !std::isfinite(d)) return false;
      const double r = std::sqrt(d);
      col_k[k] = r;
      inv_diag_[static_cast<std::size_t>(k)] = 1.0 / r;
      for (Eigen::Index i = k + 1; i < n; ++i) col_k[i] *= inv_diag_[static_cast<std::size_t>(k)];
      for (Eigen::Index j = k + 1; j < n; ++j) {
        double* __restrict col_j = l() + j * kMax;
        const double f = col_k[j];
        for (Eigen::Index i = j; i < n; ++i) col_j[i] -= col_k[i] * f;
      }
    }
    return true;
  }
  // v <- (L L^T)^-1 v with the last factor.
  void solve(Eigen::VectorXd& vec) const {
    double* __restrict v = vec.data();
    for (Eigen::Index j = 0; j < n_; ++j) {  // L y = v, column by column
      const double* col = l() + j * kMax;
      const double f = v[j] *= inv_diag_[static_cast<std::size_t>(j)];
      for (Eigen::Index i = j + 1; i < n_; ++i) v[i] -= col[i] * f;
    }
    for (Eigen::Index j = n_ - 1; j >= 0; --j) {  // L^T x = y: column j of L below the diagonal
      const double* col = l() + j * kMax;
      double s0 = 0.0, s1 = 0.0;  // two partial sums: half the dependent chain
      Eigen::Index i = j + 1;
      for (; i + 1 < n_; i += 2) {
        s0 += col[i] * v[i];
        s1 += col[i + 1] * v[i + 1];
      }
      if (i < n_) s0 += col[i] * v[i];
      v[j] = (v[j] - (s0 + s1)) * inv_diag_[static_cast<std::size_t>(j)];
    }
  }

 private:
  // No pointer into the storage is kept: a copied workspace (ClosureSolver's copy) must factor
  // into its own.
  double* l() { return l_.data(); }
  const double* l() const { return l_.data(); }

  Eigen::Index n_ = 0;
  std::array<double, kMax * kMax> l_;  // column-major, leading dimension kMax (lower)
  std::array<double, kMax> inv_diag_;
};

}  // namespace robocal::calib::detail
