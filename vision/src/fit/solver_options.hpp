#pragma once
// The Ceres options of the small dense fits (a board's pose, a hand-eye transform, internal):
// run to a tight convergence, which is cheap for a few parameters and keeps the solver's stop
// well below the measurement noise; quiet, on the caller's thread (callers fit many in
// parallel).
#include <ceres/solver.h>

namespace robocal::vision::detail {

inline ceres::Solver::Options tight_dense_fit(ceres::LinearSolverType solver, int max_iterations) {
  ceres::Solver::Options o;
  o.linear_solver_type = solver;
  o.max_num_iterations = max_iterations;
  o.function_tolerance = 1e-12;
  o.gradient_tolerance = 1e-12;
  o.parameter_tolerance = 1e-12;
  o.logging_type = ceres::SILENT;
  o.num_threads = 1;
  return o;
}

}  // namespace robocal::vision::detail
