#pragma once
// Sub-pixel straight-edge fitting on raw pixel values.
//
// Pixel convention (whole project, OpenCV's): pixel (u, v) has its centre at (u, v); the image
// covers [-0.5, w - 0.5] x [-0.5, h - 0.5].
//
// The model is a blurred step across a straight line, evaluated at pixel centres:
//   I(p) = [dark + (bright - dark) * Phi((n . (p - origin) - offset) / sigma)] * (1 + g t)
// with Phi the standard normal CDF, t = direction() . (p - origin) and g a fitted relative gain
// slope along the edge (vignetting and uneven lighting multiply the image; with constant levels
// a gain ramp along the edge would rotate the line). Fitting it directly on pixel values (no
// interpolation) keeps the estimate unbiased: the Gaussian blur of the lens and the box integration
// of the pixel are both symmetric about the edge, so they widen sigma but do not move the line.
#include <Eigen/Core>
#include <array>
#include <optional>
#include <vector>

#include <opencv2/core/mat.hpp>

namespace robocal::vision {

/// One pixel used by the edge fit: centre position (OpenCV convention) and grey value.
struct EdgeSample {
  Eigen::Vector2d position;
  double value = 0.0;
};

/// A fitted line n . (p - origin) = offset with a blurred-step intensity profile across it.
struct EdgeLineFit {
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();   ///< reference point (mean of the samples)
  Eigen::Vector2d normal = Eigen::Vector2d::UnitX();  ///< unit normal, points from dark to bright
  double offset = 0.0;                                ///< signed distance of the line from origin
  /// Quadratic bend (1/px): the edge is n.(p - origin) = offset + curvature * (t.(p - origin))^2
  /// with t = direction(); 0 for a straight fit.
  double curvature = 0.0;
  double curvature_stddev = 0.0;  ///< 1-sigma of the bend (0 for a straight fit)
  double blur_sigma = 0.0;        ///< fitted edge spread in px (lens blur + pixel integration)
  double dark = 0.0;              ///< grey level on the dark side (at the origin)
  double bright = 0.0;            ///< grey level on the bright side (at the origin)
  /// Fitted relative gain slope of the illumination along the edge (1/px, along direction()).
  double gain_slope = 0.0;
  double rms_residual = 0.0;   ///< DN
  double offset_stddev = 0.0;  ///< 1-sigma of the line offset from the fit (px)
  /// Covariance of (angle of the normal (rad), offset (px), curvature (1/px)) from the pixel
  /// noise (residual variance x (J^T J)^-1), for perturbations of this fit about `origin`;
  /// the curvature row and column are zero for a straight fit.
  Eigen::Matrix3d line_covariance = Eigen::Matrix3d::Zero();
  int samples = 0;
  bool converged = false;

  /// A point on the line and its unit direction.
  [[nodiscard]] Eigen::Vector2d point() const { return origin + offset * normal; }
  [[nodiscard]] Eigen::Vector2d direction() const { return {-normal.y(), normal.x()}; }
};

/// Fits the blurred-step model to samples, starting from the line through a and b (the samples
/// must straddle it). Returns nullopt when the fit is degenerate (too few samples, no contrast,
/// no convergence, or an implausible blur).
/// `initial_sigma` is the starting blur (px); a good value (from an earlier fit) saves iterations.
/// `curved` also fits a quadratic bend (lens distortion curves straight board edges).
std::optional<EdgeLineFit> fit_edge_line(const std::vector<EdgeSample>& samples,
                                         const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                                         double initial_sigma = 1.0, bool curved = false);

/// Intersection of two fitted edges (curved ones by Newton iteration); nullopt when they are
/// (nearly) parallel.
std::optional<Eigen::Vector2d> intersect_lines(const EdgeLineFit& l1, const EdgeLineFit& l2);

/// Refinement settings for a dark square seen against a bright surround (or the reverse).
struct QuadRefineOptions {
  /// Width of the uniform border band inside the quad, as a fraction of the side length
  /// (tag36h11: one cell of eight = 0.125). Pixels deeper inside may belong to data bits.
  double inner_band_fraction = 0.125;
  /// Width of the uniform band outside the quad as a fraction of the side length (tag36h11 quiet
  /// zone: at least one cell).
  double outer_band_fraction = 0.125;
  /// Largest edge blur the band layout allows for (px); sets how far from the neighbouring edges
  /// and from the data bits samples are taken.
  double max_blur_px = 1.6;
  /// Quads whose border band (side x fraction) is thinner than this are not refined (px).
  double min_border_px = 3.0;
  /// Fit a quadratic bend per edge (lens distortion); costs some noise on undistorted images.
  bool fit_curvature = true;
  /// Refined corners that move more than this from the initial ones are rejected (px).
  double max_shift_px = 2.0;
};

/// Result of refining the four corners of a quadrilateral.
struct QuadRefinement {
  std::array<Eigen::Vector2d, 4> corners;  ///< same order as the input corners
  std::array<EdgeLineFit, 4> edges;        ///< edge i runs from corner i to corner i+1
  double mean_blur_sigma = 0.0;            ///< mean fitted edge spread (px): the sharpness measure
  double mean_contrast = 0.0;              ///< mean |bright - dark| (DN)
  /// Joint covariance of the corners (u0, v0, u1, v1, ..., px^2), propagated from the four edge
  /// fits. Adjacent corners share an edge, so their errors are correlated: treating the corners
  /// as independent misstates how well a tag's position, size and shape are known.
  Eigen::Matrix<double, 8, 8> corner_covariance = Eigen::Matrix<double, 8, 8>::Zero();
};

/// Whether a quadrilateral's surround (the band `outer_band_fraction` of its extent beyond each
/// side: a tag's white quiet zone) lies inside the image, `margin_px` clear of its border. A quad
/// cut by the image border cannot be measured: its detected corners follow the border, and an edge
/// fit in a window the border clips locks onto the border (corners 10 px off, with a tiny sigma).
bool quad_surround_inside_image(const std::array<Eigen::Vector2d, 4>& corners,
                                double outer_band_fraction, const cv::Size& image,
                                double margin_px = 1.0);

/// Refines the corners of a quadrilateral with uniform border (an AprilTag's black border) by
/// fitting each side's edge on the full-resolution 8-bit image and intersecting adjacent sides.
/// Returns nullopt when any side cannot be fitted (the caller keeps the unrefined corners), or
/// when the quad's surround, before or after refinement, leaves the image
/// (quad_surround_inside_image: then the caller must drop the quad).
std::optional<QuadRefinement> refine_quad_corners(const cv::Mat& gray,
                                                  const std::array<Eigen::Vector2d, 4>& corners,
                                                  const QuadRefineOptions& options = {});

/// Fits one straight edge between two image points (e.g. a chessboard square side between two
/// adjacent corners), using pixels within half_width px of the segment and at least end_margin px
/// from either end. Used to measure sharpness where no quad is available.
std::optional<EdgeLineFit> fit_edge_between(const cv::Mat& gray, const Eigen::Vector2d& a,
                                            const Eigen::Vector2d& b, double half_width,
                                            double end_margin);

}  // namespace robocal::vision
