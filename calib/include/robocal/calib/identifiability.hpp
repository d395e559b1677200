#pragma once
// Identifiability of kinematic parameters from an identification Jacobian.
//
// Input: the stacked (whitened) identification Jacobian J (rows = measurement equations over the
// actual or planned poses, columns = candidate parameters) evaluated at the nominal model, and a
// readable name per column. Output: which parameters the data can identify (a base set), which
// must be held at their nominal values because they move the measurements exactly like a
// combination of others (with that combination spelled out), and which identifiable directions are
// only weakly determined (ill-conditioning, with the culprit pair).
//
// Method (documented thresholds, see IdentifiabilityOptions):
//  1. Column scaling: every column is divided by its Euclidean norm, so lengths (m) and angles
//     (rad) compete on equal terms and singular values are unit-free. A column whose norm is below
//     `no_effect_tolerance` × the largest column norm has no effect on any measurement.
//  2. Base set: columns are visited in preference order (within a class: the order of a QR
//     factorisation with column pivoting, i.e. most independent first, or with
//     `stable_tie_break` our own pivoting whose ties are broken by index); a column joins the base
//     set when its scaled column has a component of relative size > `rank_tolerance` outside the
//     span of the columns kept so far. The rest are "redundant".
//  3. Each redundant parameter f is expressed through the base set: J_f = Σ k_s J_s (least
//     squares in physical units), which is the null-space direction e_f − Σ k_s e_s. The
//     explanation names the base parameters with |k_s| scaled weight ≥ `involvement_threshold`.
//  4. Ill-conditioning: SVD of the scaled base-set Jacobian; every singular value with
//     σ_i / σ_max < `ill_conditioning_ratio` is reported with its two dominant parameters.
#include <Eigen/Core>

#include <cstddef>
#include <string>
#include <vector>

namespace robocal::calib {

struct IdentifiabilityOptions {
  // Relative size (of the column-normalised Jacobian) below which a new column is considered a
  // linear combination of the columns already kept. Structural redundancies give ~1e-12 with
  // closure Jacobians solved to 1e-12; genuinely weak but identifiable directions stay > 1e-6.
  double rank_tolerance = 1e-7;
  // A column smaller than this fraction of the largest column has no measurable effect.
  double no_effect_tolerance = 1e-10;
  // σ_i/σ_max below this (condition number > 1e3) is reported as ill-conditioned.
  double ill_conditioning_ratio = 1e-3;
  // A base parameter is named in a redundancy explanation when its scaled coefficient is at least
  // this large (scaled coefficients are unit-free: 1.0 = same effect, same size).
  double involvement_threshold = 0.05;
  // How a confounded group of equal preference is resolved (which member is kept).
  //  false (default): the pivot order of Eigen's column-pivoted QR. Among exactly confounded
  //    parameters it follows rounding-level (1e-16) differences of the input: a YAML round trip of
  //    the measured poses can change the base set and with it the held-out error.
  //  true: own greedy pivoting within each preference class: the column with the largest part
  //    outside the span of the kept columns is kept next; parts equal within a relative 1e-6 are
  //    broken by the lower parameter index. Same rank tolerance and preference semantics,
  //    deterministic under rounding noise. Not the default yet: on identify_bench rotary_delta
  //    "all" it keeps other members of first-order confounded groups and the noise-free held-out
  //    RMS goes 0.61 -> 0.69 um (calibrated vs Cramer-Rao unchanged; other seeds and robots equal).
  bool stable_tie_break = false;
};

// One parameter that cannot be separated from a combination of base parameters.
struct Redundancy {
  std::size_t parameter = 0;          // the redundant (held-fixed) parameter
  std::vector<std::size_t> partners;  // base parameters it is confused with
  // Physical coefficients: changing `parameter` by δ moves the measurements like changing
  // partners[i] by coefficients[i]·δ.
  std::vector<double> coefficients;
  double residual = 0.0;  // relative part of the scaled column outside the partners' span
  std::string explanation;
};

// A weakly determined direction among the identifiable parameters.
struct IllConditionedDirection {
  double relative_singular_value = 0.0;  // σ_i / σ_max of the scaled base-set Jacobian
  std::size_t first = 0;                 // dominant parameter of the singular vector
  std::size_t second = 0;                // second dominant parameter
  std::vector<double> direction;         // scaled singular vector over all parameters (0 off-set)
  std::string explanation;
};

struct IdentifiabilityReport {
  std::vector<std::string> names;
  Eigen::VectorXd column_norms;     // of the unscaled Jacobian
  Eigen::VectorXd singular_values;  // of the full column-scaled Jacobian, descending
  std::size_t rows = 0;
  std::size_t rank = 0;                   // = identifiable.size()
  std::vector<std::size_t> identifiable;  // base set, ascending indices
  std::vector<std::size_t> redundant;     // held at nominal, ascending (includes no_effect)
  std::vector<std::size_t> no_effect;     // columns that do not change any measurement
  std::vector<Redundancy> redundancies;   // one per redundant parameter that has an effect
  std::vector<IllConditionedDirection> ill_conditioned;
  double condition_number = 0.0;      // of the scaled base-set Jacobian
  bool underdetermined = false;       // fewer equations than candidate parameters
  std::vector<std::string> messages;  // the whole analysis in plain words

  bool is_identifiable(std::size_t parameter) const;
};

// `J` must have one column per name. `preference` (optional, same length as names) orders the
// base-set search: lower values are kept first when two parameters are confounded (e.g. prefer
// geometry over the tool frame). Throws std::invalid_argument on size mismatch or non-finite J.
IdentifiabilityReport analyze_identifiability(const Eigen::MatrixXd& J,
                                              const std::vector<std::string>& names,
                                              const IdentifiabilityOptions& options = {},
                                              const std::vector<int>& preference = {});

}  // namespace robocal::calib
