#include "robocal/vision/edge_fit.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

namespace robocal::vision {
namespace {

constexpr double kInvSqrt2 = 0.70710678118654752440;
constexpr double kInvSqrt2Pi = 0.39894228040143267794;

double normal_cdf(double z) {
  return 0.5 * std::erfc(-z * kInvSqrt2);
}

// Parameters of the blurred-step model: angle of the normal, line offset, dark level, contrast,
// log of the blur sigma (log keeps sigma positive without constraints), the gain slopes and the
// bend.
struct StepParams {
  double theta = 0.0;
  double offset = 0.0;
  double dark = 0.0;
  double contrast = 0.0;
  double log_sigma = 0.0;
  double curvature = 0.0;  // px^-1: the edge bends by curvature * t^2 at t px along it
  // Relative gain slope (1/px) along the edge about the origin: vignetting and uneven lighting
  // multiply the image by a gain that changes over the band, and with constant levels a ramp
  // along the edge rotates the fitted line (its brighter end looks like more bright paper). A
  // ramp across the edge moves it by only ~slope * sigma^2 and is left out: over the narrow
  // bands of foreshortened tags it would trade against the offset.
  double gain = 0.0;
};

// Parameter indices of the fit: theta, offset, dark, contrast, log sigma, gain slope, and the
// curvature last when it is fitted.
constexpr int kGain = 5;
constexpr int kStraightParams = 6;
constexpr int kCurvature = 6;

// Phi(z) and phi(z) sharing one exp(): erfc by Abramowitz & Stegun 7.1.26 (|error| < 1.5e-7,
// i.e. < 3e-5 DN at 200 DN contrast). The fit spends nearly all its time here.
inline void cdf_pdf(double z, double* cdf, double* pdf) {
  const double e = std::exp(-0.5 * z * z);
  *pdf = kInvSqrt2Pi * e;
  const double x = std::abs(z) * kInvSqrt2;
  const double t = 1.0 / (1.0 + 0.3275911 * x);
  const double tail =
      0.5 * t *
      (0.254829592 +
       t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429)))) *
      e;
  *cdf = z >= 0.0 ? 1.0 - tail : tail;
}

// Sum of squared residuals of the model and, in the same pass, J^T J and J^T r. The signed
// distance from the (slightly curved) edge is s = n.q - offset - curvature (t.q)^2 with q the
// sample relative to the origin and t the direction along the edge: lens distortion bends
// straight board edges, and a 50 px edge of a tag near the image border easily bows by 0.2 px.
template <int N>
double evaluate(const std::vector<EdgeSample>& samples, const Eigen::Vector2d& origin,
                const StepParams& p, Eigen::Matrix<double, N, N>* jtj,
                Eigen::Matrix<double, N, 1>* jtr) {
  const Eigen::Vector2d n(std::cos(p.theta), std::sin(p.theta));
  const Eigen::Vector2d dn(-n.y(), n.x());
  const double sigma = std::exp(p.log_sigma);
  const double inv_sigma = 1.0 / sigma;
  jtj->setZero();
  jtr->setZero();
  double cost = 0.0;
  for (const auto& s : samples) {
    const Eigen::Vector2d q = s.position - origin;
    const double along = dn.dot(q);
    const double across = n.dot(q);
    const double z = (across - p.offset - p.curvature * along * along) * inv_sigma;
    double cdf = 0.0;
    double pdf = 0.0;
    cdf_pdf(z, &cdf, &pdf);
    const double base = p.dark + p.contrast * cdf;
    const double gain = 1.0 + p.gain * along;
    const double r = base * gain - s.value;
    const double g = gain * p.contrast * pdf * inv_sigma;
    Eigen::Matrix<double, N, 1> j;
    // d along / d theta = -across: the gain ramp turns with the line.
    j(0) = g * (along + 2.0 * p.curvature * along * across) - base * p.gain * across;
    j(1) = -g;
    j(2) = gain;
    j(3) = gain * cdf;
    j(4) = -g * sigma * z;
    j(kGain) = base * along;
    if constexpr (N > kStraightParams) j(kCurvature) = -g * along * along;
    jtj->template selfadjointView<Eigen::Lower>().rankUpdate(j);
    *jtr += j * r;
    cost += r * r;
  }
  *jtj = jtj->template selfadjointView<Eigen::Lower>();
  return cost;
}

// Dark level and contrast by linear least squares for a fixed line and blur.
bool solve_levels(const std::vector<EdgeSample>& samples, const Eigen::Vector2d& origin,
                  StepParams& p) {
  const Eigen::Vector2d n(std::cos(p.theta), std::sin(p.theta));
  const double sigma = std::exp(p.log_sigma);
  Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
  Eigen::Vector2d atb = Eigen::Vector2d::Zero();
  for (const auto& s : samples) {
    const double f = normal_cdf((n.dot(s.position - origin) - p.offset) / sigma);
    ata(0, 0) += 1.0;
    ata(0, 1) += f;
    ata(1, 1) += f * f;
    atb(0) += s.value;
    atb(1) += f * s.value;
  }
  ata(1, 0) = ata(0, 1);
  if (std::abs(ata.determinant()) < 1e-9 * ata(0, 0) * ata(0, 0)) return false;
  const Eigen::Vector2d x = ata.ldlt().solve(atb);
  p.dark = x(0);
  p.contrast = x(1);
  return true;
}

}  // namespace

namespace {

template <int N>
std::optional<EdgeLineFit> fit_edge(const std::vector<EdgeSample>& samples,
                                    const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                                    double initial_sigma) {
  constexpr int kMinSamples = 12;
  if (static_cast<int>(samples.size()) < kMinSamples) return std::nullopt;
  const Eigen::Vector2d dir = b - a;
  if (dir.norm() < 1e-6) return std::nullopt;

  Eigen::Vector2d origin = Eigen::Vector2d::Zero();
  for (const auto& s : samples) origin += s.position;
  origin /= static_cast<double>(samples.size());

  StepParams p;
  const Eigen::Vector2d n0 = Eigen::Vector2d(-dir.y(), dir.x()).normalized();
  p.theta = std::atan2(n0.y(), n0.x());
  p.offset = n0.dot(a - origin);
  p.log_sigma = std::log(std::clamp(initial_sigma, 0.1, 8.0));
  if (!solve_levels(samples, origin, p)) return std::nullopt;

  // Levenberg-Marquardt on the N parameters; the problem is small (a few hundred samples).
  Eigen::Matrix<double, N, N> jtj;
  Eigen::Matrix<double, N, 1> jtr;
  double cost = evaluate<N>(samples, origin, p, &jtj, &jtr);
  double lambda = 1e-3;
  bool converged = false;
  double last_offset_step = 1.0;
  // Stage 0 holds the gain slope at zero (the constant-level fit, robust from a rough start);
  // stage 1 frees it from there. Freed from the start, the extra freedom let some fits on real,
  // JPEG-compressed tags run off to a degenerate, needle-sharp step.
  StepParams constant_levels;
  double constant_cost = 0.0;
  bool constant_converged = false;
  Eigen::Matrix<double, N, N> constant_jtj = jtj;
  for (int stage = 0; stage < 2; ++stage) {
    if (stage == 1) {
      constant_levels = p;
      constant_cost = cost;
      constant_converged = converged;
      constant_jtj = jtj;
    }
    converged = false;
    lambda = 1e-3;
    for (int iter = 0; iter < 100 && !converged; ++iter) {
      bool stepped = false;
      for (int attempt = 0; attempt < 10 && !stepped; ++attempt) {
        Eigen::Matrix<double, N, N> damped = jtj;
        for (int k = 0; k < N; ++k) damped(k, k) += lambda * std::max(jtj(k, k), 1e-12);
        Eigen::Matrix<double, N, 1> rhs = -jtr;
        if (stage == 0) {
          damped.row(kGain).setZero();
          damped.col(kGain).setZero();
          damped(kGain, kGain) = 1.0;
          rhs(kGain) = 0.0;
        }
        const Eigen::Matrix<double, N, 1> delta = damped.ldlt().solve(rhs);
        if (!delta.allFinite()) return std::nullopt;
        StepParams trial = p;
        trial.theta += delta(0);
        trial.offset += delta(1);
        trial.dark += delta(2);
        trial.contrast += delta(3);
        trial.log_sigma = std::clamp(p.log_sigma + delta(4), std::log(0.05), std::log(20.0));
        trial.gain += delta(kGain);
        if constexpr (N > kStraightParams) trial.curvature += delta(kCurvature);
        Eigen::Matrix<double, N, N> trial_jtj;
        Eigen::Matrix<double, N, 1> trial_jtr;
        const double trial_cost = evaluate<N>(samples, origin, trial, &trial_jtj, &trial_jtr);
        if (trial_cost <= cost) {
          // 1e-4 px / 1e-6 rad steps are far below any accuracy that matters here.
          const bool small = std::abs(delta(1)) < 1e-4 && std::abs(delta(0)) < 1e-6;
          const bool flat = cost - trial_cost <= 1e-10 * std::max(cost, 1.0);
          last_offset_step = std::abs(delta(1));
          p = trial;
          cost = trial_cost;
          jtj = trial_jtj;
          jtr = trial_jtr;
          lambda = std::max(lambda / 4.0, 1e-9);
          stepped = true;
          if (small || flat) converged = true;
        } else {
          lambda *= 8.0;
        }
      }
      if (!stepped) converged = true;  // no decrease possible: at a minimum to machine precision
    }
  }
  // A gain slope that ran off (the step collapsing to a needle, or a gain change of over 50%
  // across the band) is not illumination: keep the constant-level fit.
  double half_length = 0.0;
  {
    const Eigen::Vector2d t(-std::sin(p.theta), std::cos(p.theta));
    for (const auto& smp : samples)
      half_length = std::max(half_length, std::abs(t.dot(smp.position - origin)));
  }
  if (std::exp(p.log_sigma) < 0.1 || std::abs(p.gain) * half_length > 0.5) {
    p = constant_levels;
    cost = constant_cost;
    converged = constant_converged;
    jtj = constant_jtj;
    jtj.row(kGain).setZero();
    jtj.col(kGain).setZero();
    jtj(kGain, kGain) = 1.0;
  }
  if (!converged && last_offset_step > 1e-3) return std::nullopt;

  EdgeLineFit fit;
  fit.origin = origin;
  fit.normal = Eigen::Vector2d(std::cos(p.theta), std::sin(p.theta));
  fit.offset = p.offset;
  fit.curvature = p.curvature;
  fit.blur_sigma = std::exp(p.log_sigma);
  fit.dark = p.dark;
  fit.bright = p.dark + p.contrast;
  fit.gain_slope = p.gain;
  fit.samples = static_cast<int>(samples.size());
  const double dof = std::max(1.0, static_cast<double>(samples.size()) - N);
  fit.rms_residual = std::sqrt(cost / static_cast<double>(samples.size()));
  const Eigen::Matrix<double, N, N> cov = jtj.inverse() * (cost / dof);
  fit.offset_stddev = std::sqrt(std::max(0.0, cov(1, 1)));
  if constexpr (N > kStraightParams)
    fit.curvature_stddev = std::sqrt(std::max(0.0, cov(kCurvature, kCurvature)));
  {
    // (theta, offset[, curvature]) block; the sign flip below negates offset and curvature.
    constexpr int kLine[3] = {0, 1, N > kStraightParams ? kCurvature : -1};
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        fit.line_covariance(r, c) = kLine[r] < 0 || kLine[c] < 0 ? 0.0 : cov(kLine[r], kLine[c]);
  }
  if (p.contrast < 0.0) {  // orient the normal from dark to bright
    fit.normal = -fit.normal;
    fit.offset = -fit.offset;
    fit.curvature = -fit.curvature;
    std::swap(fit.dark, fit.bright);
    const Eigen::Matrix3d flip = Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
    fit.line_covariance = flip * fit.line_covariance * flip;
  }
  const double contrast = fit.bright - fit.dark;
  // Implausible fits: no real edge (contrast lost in noise) or a spread no lens produces.
  if (!(contrast > 4.0 * fit.rms_residual) || contrast < 3.0 || fit.blur_sigma < 0.1 ||
      fit.blur_sigma > 8.0 || !std::isfinite(fit.offset)) {
    return std::nullopt;
  }
  fit.converged = true;
  return fit;
}

}  // namespace

std::optional<EdgeLineFit> fit_edge_line(const std::vector<EdgeSample>& samples,
                                         const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                                         double initial_sigma, bool curved) {
  // The bend is always kept when asked for: dropping insignificant bends (a significance test)
  // was measured to leave a 0.15 px (8 sigma) focal-length bias on a k1 = -0.18 lens; the bend
  // costs some noise instead, which averages out over many corners.
  if (curved) return fit_edge<kStraightParams + 1>(samples, a, b, initial_sigma);
  return fit_edge<kStraightParams>(samples, a, b, initial_sigma);
}

std::optional<Eigen::Vector2d> intersect_lines(const EdgeLineFit& l1, const EdgeLineFit& l2) {
  Eigen::Matrix2d a;
  a.row(0) = l1.normal.transpose();
  a.row(1) = l2.normal.transpose();
  const double det = a.determinant();
  if (std::abs(det) < 1e-3) return std::nullopt;  // within ~0.06 deg of parallel
  const Eigen::Vector2d rhs(l1.normal.dot(l1.point()), l2.normal.dot(l2.point()));
  Eigen::Vector2d p = a.inverse() * rhs;
  if (l1.curvature == 0.0 && l2.curvature == 0.0) return p;
  // Curved edges: Newton on the two signed distances, from the straight-line intersection.
  for (int iter = 0; iter < 10; ++iter) {
    Eigen::Vector2d f;
    Eigen::Matrix2d j;
    const EdgeLineFit* e[2] = {&l1, &l2};
    for (int k = 0; k < 2; ++k) {
      const Eigen::Vector2d q = p - e[k]->origin;
      const Eigen::Vector2d t = e[k]->direction();
      const double along = t.dot(q);
      f(k) = e[k]->normal.dot(q) - e[k]->offset - e[k]->curvature * along * along;
      j.row(k) = (e[k]->normal - 2.0 * e[k]->curvature * along * t).transpose();
    }
    if (std::abs(j.determinant()) < 1e-6) return std::nullopt;
    const Eigen::Vector2d step = j.inverse() * f;
    p -= step;
    if (step.norm() < 1e-9) break;
  }
  if (!p.allFinite()) return std::nullopt;
  return p;
}

namespace {

// Pixels of an 8-bit image inside the band of edge i of a quad: within [-outer, inner] of the
// edge (inner = towards the quad centre), between its end points, and at least `margin` px from
// the lines of the two neighbouring edges (whose blur would distort the step profile).
std::vector<EdgeSample> quad_edge_samples(const cv::Mat& gray,
                                          const std::array<Eigen::Vector2d, 4>& c, int i,
                                          double inner, double outer, double margin,
                                          bool half_density) {
  const Eigen::Vector2d& p0 = c[static_cast<size_t>(i)];
  const Eigen::Vector2d& p1 = c[static_cast<size_t>((i + 1) % 4)];
  const Eigen::Vector2d centre = (c[0] + c[1] + c[2] + c[3]) / 4.0;
  const double len = (p1 - p0).norm();
  const Eigen::Vector2d u = (p1 - p0) / len;
  Eigen::Vector2d n_in(-u.y(), u.x());
  if (n_in.dot(centre - p0) < 0.0) n_in = -n_in;

  auto line_distance = [&](int k, const Eigen::Vector2d& p) {
    const Eigen::Vector2d& a = c[static_cast<size_t>((k + 4) % 4)];
    const Eigen::Vector2d& b = c[static_cast<size_t>((k + 5) % 4)];
    const Eigen::Vector2d d = (b - a).normalized();
    const Eigen::Vector2d q = p - a;
    return std::abs(d.x() * q.y() - d.y() * q.x());
  };

  const double reach = std::max(inner, outer);
  const int x0 = std::max(0, static_cast<int>(std::floor(std::min(p0.x(), p1.x()) - reach)));
  const int x1 =
      std::min(gray.cols - 1, static_cast<int>(std::ceil(std::max(p0.x(), p1.x()) + reach)));
  const int y0 = std::max(0, static_cast<int>(std::floor(std::min(p0.y(), p1.y()) - reach)));
  const int y1 =
      std::min(gray.rows - 1, static_cast<int>(std::ceil(std::max(p0.y(), p1.y()) + reach)));
  std::vector<EdgeSample> samples;
  for (int y = y0; y <= y1; ++y) {
    const auto* row = gray.ptr<unsigned char>(y);
    for (int x = x0; x <= x1; ++x) {
      if (half_density && ((x + y) & 1) != 0) continue;
      const Eigen::Vector2d p(x, y);
      const Eigen::Vector2d q = p - p0;
      const double t = u.dot(q);
      const double depth = n_in.dot(q);
      if (t < 0.0 || t > len || depth > inner || depth < -outer) continue;
      if (line_distance(i - 1, p) < margin || line_distance(i + 1, p) < margin) continue;
      samples.push_back({p, static_cast<double>(row[x])});
    }
  }
  return samples;
}

// The quad's extent perpendicular to each edge (edge i from corner i to i+1): the distance to
// the nearer end of the opposite edge.
std::array<double, 4> quad_extents(const std::array<Eigen::Vector2d, 4>& corners) {
  std::array<double, 4> extent{};
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector2d& a = corners[static_cast<size_t>(i)];
    const Eigen::Vector2d d = (corners[static_cast<size_t>((i + 1) % 4)] - a).normalized();
    double e = std::numeric_limits<double>::infinity();
    for (int k = 2; k < 4; ++k) {
      const Eigen::Vector2d q = corners[static_cast<size_t>((i + k) % 4)] - a;
      e = std::min(e, std::abs(d.x() * q.y() - d.y() * q.x()));
    }
    extent[static_cast<size_t>(i)] = e;
  }
  return extent;
}

// First-order propagation of the four edges (angle, offset, curvature) covariances to the
// corners they intersect in (corner i = edge i-1 x edge i), by central differences.
Eigen::Matrix<double, 8, 8> propagate_corner_covariance(const std::array<EdgeLineFit, 4>& edges,
                                                        const std::array<Eigen::Vector2d, 4>& at) {
  Eigen::Matrix<double, 8, 8> cov = Eigen::Matrix<double, 8, 8>::Zero();
  for (size_t e = 0; e < 4; ++e) {
    Eigen::Matrix<double, 8, 3> j = Eigen::Matrix<double, 8, 3>::Zero();
    const double steps[3] = {1e-6, 1e-5, 1e-8};
    for (int p = 0; p < 3; ++p) {
      std::array<Eigen::Vector2d, 4> hi = at;
      std::array<Eigen::Vector2d, 4> lo = at;
      for (int sign : {1, -1}) {
        EdgeLineFit f = edges[e];
        const double h = sign * steps[p];
        if (p == 0) {
          const Eigen::Rotation2Dd rot(h);
          // Rotate about the origin: the offset is measured from there along the normal.
          f.normal = rot * f.normal;
        } else if (p == 1) {
          f.offset += h;
        } else {
          f.curvature += h;
        }
        for (size_t c : {e, (e + 1) % 4}) {
          // Corner c is the intersection of edges c-1 and c.
          const EdgeLineFit& a = c == e ? edges[(e + 3) % 4] : f;
          const EdgeLineFit& b = c == e ? f : edges[(e + 1) % 4];
          const auto q = intersect_lines(a, b);
          (sign > 0 ? hi : lo)[c] = q ? *q : at[c];
        }
      }
      for (size_t c : {e, (e + 1) % 4})
        j.block<2, 1>(static_cast<Eigen::Index>(2 * c), p) = (hi[c] - lo[c]) / (2.0 * steps[p]);
    }
    cov += j * edges[e].line_covariance * j.transpose();
  }
  return 0.5 * (cov + cov.transpose());
}

}  // namespace

bool quad_surround_inside_image(const std::array<Eigen::Vector2d, 4>& corners,
                                double outer_band_fraction, const cv::Size& image,
                                double margin_px) {
  const std::array<double, 4> extent = quad_extents(corners);
  const Eigen::Vector2d centre = (corners[0] + corners[1] + corners[2] + corners[3]) / 4.0;
  // Each side moved outwards by its band; the surround's corners are where adjacent moved sides
  // meet.
  std::array<Eigen::Vector2d, 4> point;
  std::array<Eigen::Vector2d, 4> direction;
  for (size_t i = 0; i < 4; ++i) {
    const Eigen::Vector2d& a = corners[i];
    const Eigen::Vector2d d = corners[(i + 1) % 4] - a;
    if (d.norm() < 1e-9) return false;
    direction[i] = d.normalized();
    Eigen::Vector2d out(direction[i].y(), -direction[i].x());
    if (out.dot(centre - a) > 0.0) out = -out;
    point[i] = a + outer_band_fraction * extent[i] * out;
  }
  const double lo = -0.5 + margin_px;
  const double hi_u = image.width - 0.5 - margin_px;
  const double hi_v = image.height - 0.5 - margin_px;
  for (size_t k = 0; k < 4; ++k) {
    const size_t e1 = (k + 3) % 4;  // corner k joins edges k-1 and k
    const Eigen::Vector2d& d1 = direction[e1];
    const Eigen::Vector2d& d2 = direction[k];
    const double den = d1.x() * d2.y() - d1.y() * d2.x();
    if (std::abs(den) < 1e-9) return false;
    const Eigen::Vector2d w = point[k] - point[e1];
    const double s = (w.x() * d2.y() - w.y() * d2.x()) / den;
    const Eigen::Vector2d q = point[e1] + s * d1;
    if (!(q.x() >= lo && q.x() <= hi_u && q.y() >= lo && q.y() <= hi_v)) return false;
  }
  return true;
}

std::optional<QuadRefinement> refine_quad_corners(const cv::Mat& gray,
                                                  const std::array<Eigen::Vector2d, 4>& corners,
                                                  const QuadRefineOptions& options) {
  if (gray.empty() || gray.type() != CV_8UC1) return std::nullopt;
  if (!quad_surround_inside_image(corners, options.outer_band_fraction, gray.size())) {
    return std::nullopt;
  }
  double side = 0.0;
  for (int i = 0; i < 4; ++i) {
    const double len =
        (corners[static_cast<size_t>((i + 1) % 4)] - corners[static_cast<size_t>(i)]).norm();
    if (len < 8.0) return std::nullopt;
    side += len / 4.0;
  }
  // Depth of the border cell behind each edge, measured across that edge: a fraction of the
  // quad's extent perpendicular to it. A tilted tag is foreshortened across two of its edges
  // only; a band sized from the mean side length reached into the data bits there (a white bit
  // pulls the fitted edge inwards: a shrink bias).
  const std::array<double, 4> extent = quad_extents(corners);
  std::array<double, 4> inner_cell{};
  std::array<double, 4> outer_cell{};
  for (size_t i = 0; i < 4; ++i) {
    inner_cell[i] = options.inner_band_fraction * extent[i];
    outer_cell[i] = options.outer_band_fraction * extent[i];
    // The step model needs a uniform border at least a few pixels deep on both sides; narrower
    // borders put the data bits inside the fitted band and would pull the line.
    if (std::min(inner_cell[i], outer_cell[i]) < options.min_border_px) return std::nullopt;
  }

  // Two passes: the first, with a conservative band, measures the blur; the second widens the
  // band as far as that blur allows without seeing the data bits or the neighbouring edges.
  QuadRefinement result;
  result.corners = corners;
  double blur = options.max_blur_px;
  for (int pass = 0; pass < 2; ++pass) {
    // Pass 1 only needs the blur and a rough line: most of a cell, some contamination accepted.
    // Pass 2 keeps 2.5 sigma (+ half a pixel) away from the data bits and neighbouring edges.
    const double keep_off = pass == 0 ? std::max(2.0, 0.2 * side) : 0.5 + 2.5 * blur;
    // Beyond ~4 sigma from the edge pixels only repeat the plateau levels: skip them (speed).
    const double useful = 1.5 + 4.0 * blur;
    std::array<EdgeLineFit, 4> edges;
    for (int i = 0; i < 4; ++i) {
      const double ic = inner_cell[static_cast<size_t>(i)];
      const double oc = outer_cell[static_cast<size_t>(i)];
      const double inner =
          pass == 0 ? std::max(2.0, 0.8 * ic) : std::max(2.0, std::min(ic - keep_off, useful));
      const double outer =
          pass == 0 ? std::max(2.0, 0.8 * oc) : std::max(2.0, std::min(oc - keep_off, useful));
      // Pass 1 only locates the edge roughly: every other pixel (checkerboard) is enough.
      const auto samples =
          quad_edge_samples(gray, result.corners, i, inner, outer, keep_off, pass == 0);
      const double start_sigma = pass == 0 ? 1.0 : result.edges[static_cast<size_t>(i)].blur_sigma;
      // The bend is fitted in the final pass only (it needs the accurate band).
      const auto fit = fit_edge_line(samples, result.corners[static_cast<size_t>(i)],
                                     result.corners[static_cast<size_t>((i + 1) % 4)], start_sigma,
                                     pass == 1 && options.fit_curvature);
      if (!fit) return std::nullopt;
      edges[static_cast<size_t>(i)] = *fit;
    }
    std::array<Eigen::Vector2d, 4> refined;
    for (int i = 0; i < 4; ++i) {
      const auto corner =
          intersect_lines(edges[static_cast<size_t>((i + 3) % 4)], edges[static_cast<size_t>(i)]);
      if (!corner) return std::nullopt;
      if ((*corner - corners[static_cast<size_t>(i)]).norm() > options.max_shift_px) {
        return std::nullopt;
      }
      refined[static_cast<size_t>(i)] = *corner;
    }
    result.corners = refined;
    result.edges = edges;
    if (pass == 1) result.corner_covariance = propagate_corner_covariance(edges, refined);
    double mean_blur = 0.0;
    double contrast = 0.0;
    for (const auto& e : edges) {
      mean_blur += e.blur_sigma / 4.0;
      contrast += (e.bright - e.dark) / 4.0;
    }
    result.mean_blur_sigma = mean_blur;
    result.mean_contrast = contrast;
    blur = std::clamp(mean_blur, 0.3, options.max_blur_px);
  }
  if (!quad_surround_inside_image(result.corners, options.outer_band_fraction, gray.size())) {
    return std::nullopt;
  }
  return result;
}

std::optional<EdgeLineFit> fit_edge_between(const cv::Mat& gray, const Eigen::Vector2d& a,
                                            const Eigen::Vector2d& b, double half_width,
                                            double end_margin) {
  if (gray.empty() || gray.type() != CV_8UC1) return std::nullopt;
  const double len = (b - a).norm();
  if (len <= 2.0 * end_margin + 2.0) return std::nullopt;
  const Eigen::Vector2d u = (b - a) / len;
  const Eigen::Vector2d n(-u.y(), u.x());
  const int x0 = std::max(0, static_cast<int>(std::floor(std::min(a.x(), b.x()) - half_width)));
  const int x1 =
      std::min(gray.cols - 1, static_cast<int>(std::ceil(std::max(a.x(), b.x()) + half_width)));
  const int y0 = std::max(0, static_cast<int>(std::floor(std::min(a.y(), b.y()) - half_width)));
  const int y1 =
      std::min(gray.rows - 1, static_cast<int>(std::ceil(std::max(a.y(), b.y()) + half_width)));
  std::vector<EdgeSample> samples;
  for (int y = y0; y <= y1; ++y) {
    const auto* row = gray.ptr<unsigned char>(y);
    for (int x = x0; x <= x1; ++x) {
      const Eigen::Vector2d q = Eigen::Vector2d(x, y) - a;
      const double t = u.dot(q);
      if (t < end_margin || t > len - end_margin || std::abs(n.dot(q)) > half_width) continue;
      samples.push_back({Eigen::Vector2d(x, y), static_cast<double>(row[x])});
    }
  }
  return fit_edge_line(samples, a, b);
}

}  // namespace robocal::vision
