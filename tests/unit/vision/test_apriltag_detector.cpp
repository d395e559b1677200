// AprilTag detection against rendered ground truth and the upstream AprilTag test photographs.
#include "real_data.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

#include "robocal/core/random_draws.hpp"
#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/edge_fit.hpp"
#include "synthetic_tags.hpp"

namespace rv = robocal::vision;
namespace rt = robocal::testing;

namespace {

struct ErrorStats {
  double rms = 0.0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  double radial = 0.0;  // mean signed error away from the tag centre
  int corners = 0;
};

ErrorStats compare(const std::vector<rv::TagDetection>& found,
                   const std::vector<rt::SyntheticTag>& truth, bool library_corners) {
  ErrorStats s;
  for (const auto& t : truth) {
    for (const auto& d : found) {
      if (d.id != t.id) continue;
      const Eigen::Vector2d centre =
          (t.corners[0] + t.corners[1] + t.corners[2] + t.corners[3]) / 4;
      for (size_t k = 0; k < 4; ++k) {
        const Eigen::Vector2d e =
            (library_corners ? d.library_corners[k] : d.corners[k]) - t.corners[k];
        s.rms += e.squaredNorm();
        s.mean += e;
        s.radial += e.dot((t.corners[k] - centre).normalized());
        ++s.corners;
      }
    }
  }
  if (s.corners > 0) {
    s.rms = std::sqrt(s.rms / s.corners);
    s.mean /= s.corners;
    s.radial /= s.corners;
  }
  return s;
}

// A 640x512 view of a 4x3 grid of 50 mm tags at 600 mm: tags ~50 px across (the size of the
// issue's accuracy requirement and of bench_vision_accuracy's nominal case).
struct Scene {
  rt::SyntheticCamera cam{640, 512, 600.0, 319.5, 255.5};
  rt::TagGridRenderer renderer{rt::TagGrid{4, 3, 50.0, 12.5, 0}};

  cv::Mat render(double tilt_deg, double blur, double noise, unsigned seed,
                 std::vector<rt::SyntheticTag>* truth, double u = 319.5, double v = 255.5,
                 rt::SyntheticImageOptions opt = {}) const {
    const auto [r, t] =
        rt::look_at_pose(cam, renderer.board_size() / 2, 600.0, tilt_deg, 30.0, 8.0, u, v);
    opt.blur_sigma = blur;
    opt.noise_sigma = noise;
    opt.seed = seed;
    return renderer.render(cam, rt::board_homography(cam, r, t), opt, truth);
  }
};

}  // namespace

// The detector's requirement at blur 0.8 px / noise 2 DN / tilt up to 45 deg: RMS <= 0.03 px.
// Bias limits here are 0.01 px: with ~80 corners per case the mean's own noise is ~0.002 px; the
// 0.005 px limit is checked over the full sweep by bench_vision_accuracy.
TEST(AprilTagDetector, RefinedCornersMeetAccuracyOnRenderedViews) {
  Scene scene;
  rv::AprilTagDetector detector;
  for (double tilt : {0.0, 45.0}) {
    std::vector<rt::SyntheticTag> truth;
    const cv::Mat img = scene.render(tilt, 0.8, 2.0, 7, &truth);
    const auto found = detector.detect(img);
    ASSERT_EQ(found.size(), truth.size()) << "tilt " << tilt;
    for (const auto& d : found) EXPECT_TRUE(d.refined) << "tag " << d.id;
    const ErrorStats ours = compare(found, truth, false);
    const ErrorStats lib = compare(found, truth, true);
    EXPECT_EQ(ours.corners, 4 * static_cast<int>(truth.size()));
    EXPECT_LE(ours.rms, 0.03) << "tilt " << tilt;
    EXPECT_LE(std::abs(ours.mean.x()), 0.01);
    EXPECT_LE(std::abs(ours.mean.y()), 0.01);
    EXPECT_LE(std::abs(ours.radial), 0.01);
    // Our refinement must beat the library it starts from.
    EXPECT_LT(ours.rms, 0.6 * lib.rms) << "ours " << ours.rms << " library " << lib.rms;
  }
}

// Without the -0.5 px shift every library corner would be off by (+0.5, +0.5); with it the
// library's corners are unbiased to well under 0.1 px.
// The joint covariance of a tag's four corners, propagated from its edge fits, against the
// actual errors over noisy renders of strongly tilted (foreshortened) tags: the mean of
// e^T C^-1 e over tags is 8 (the dimension) when C is right. Adjacent corners share a fitted
// (curved) edge and their errors along its normal are positively correlated: assuming
// independent corners would understate how far a tag as a whole can move.
TEST(AprilTagDetector, CornerCovarianceMatchesTheSpreadOfNoisyRenders) {
  Scene scene;
  rv::AprilTagDetector detector;
  double whitened = 0.0, same_edge = 0.0, n1 = 0.0, n2 = 0.0;
  int tags = 0;
  for (unsigned seed = 1; seed <= 6; ++seed) {
    std::vector<rt::SyntheticTag> truth;
    const cv::Mat img = scene.render(50.0, 0.8, 2.0, seed, &truth);
    for (const auto& d : detector.detect(img)) {
      for (const auto& t : truth) {
        if (t.id != d.id || !d.refined) continue;
        Eigen::Matrix<double, 8, 1> e;
        for (size_t k = 0; k < 4; ++k)
          e.segment<2>(static_cast<Eigen::Index>(2 * k)) = d.corners[k] - t.corners[k];
        whitened += e.dot(d.corner_covariance.ldlt().solve(e));
        for (size_t k = 0; k < 4; ++k) {
          const Eigen::Vector2d dir = (t.corners[(k + 1) % 4] - t.corners[k]).normalized();
          const Eigen::Vector2d n(-dir.y(), dir.x());
          const double a = e.segment<2>(static_cast<Eigen::Index>(2 * k)).dot(n);
          const double b = e.segment<2>(static_cast<Eigen::Index>(2 * ((k + 1) % 4))).dot(n);
          same_edge += a * b;
          n1 += a * a;
          n2 += b * b;
        }
        ++tags;
      }
    }
  }
  ASSERT_GE(tags, 60);
  const double mean = whitened / tags;  // chi-square with 8 dof: mean 8, sd of the mean ~0.5
  EXPECT_GT(mean, 6.0);
  EXPECT_LT(mean, 11.0);
  EXPECT_GT(same_edge / std::sqrt(n1 * n2), 0.15);
}

TEST(AprilTagDetector, LibraryCornersAreShiftedToOpenCvConvention) {
  Scene scene;
  rv::AprilTagDetectorOptions opt;
  opt.subpixel_refine = false;
  rv::AprilTagDetector detector(opt);
  std::vector<rt::SyntheticTag> truth;
  const cv::Mat img = scene.render(20.0, 0.8, 1.0, 3, &truth);
  const auto found = detector.detect(img);
  ASSERT_EQ(found.size(), truth.size());
  const ErrorStats lib = compare(found, truth, true);
  EXPECT_LT(std::abs(lib.mean.x()), 0.1);
  EXPECT_LT(std::abs(lib.mean.y()), 0.1);
  EXPECT_LT(lib.rms, 0.2);
  for (const auto& d : found) {
    EXPECT_FALSE(d.refined);
    EXPECT_TRUE(std::isnan(d.edge_blur_px));
  }
}

// The refinement must not depend on where it starts: from truth perturbed by up to 0.8 px in
// random directions it lands on the truth (to the noise level), not near its start.
TEST(QuadRefinement, ConvergesFromPerturbedCorners) {
  Scene scene;
  std::vector<rt::SyntheticTag> truth;
  const cv::Mat img = scene.render(30.0, 0.8, 2.0, 5, &truth);
  ASSERT_FALSE(truth.empty());
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> jitter(-0.8, 0.8);
  double sq = 0.0;
  int n = 0;
  for (const auto& tag : truth) {
    std::array<Eigen::Vector2d, 4> start = tag.corners;
    for (auto& c : start) c += robocal::core::draw_vector2(jitter, rng);
    const auto refined = rv::refine_quad_corners(img, start);
    ASSERT_TRUE(refined.has_value()) << "tag " << tag.id;
    for (size_t k = 0; k < 4; ++k) {
      const double e = (refined->corners[k] - tag.corners[k]).norm();
      EXPECT_LT(e, 0.1) << "tag " << tag.id << " corner " << k;
      sq += e * e;
      ++n;
    }
  }
  EXPECT_LT(std::sqrt(sq / n), 0.03);
}

TEST(AprilTagDetector, EdgeBlurMeasureGrowsWithBlur) {
  Scene scene;
  rv::AprilTagDetector detector;
  double previous = 0.0;
  for (double blur : {0.0, 0.5, 0.8, 1.2, 1.6, 2.0}) {
    const cv::Mat img = scene.render(25.0, blur, 2.0, 11, nullptr);
    const auto found = detector.detect(img);
    ASSERT_FALSE(found.empty()) << "blur " << blur;
    double mean = 0.0;
    int n = 0;
    for (const auto& d : found) {
      if (!d.refined) continue;
      mean += d.edge_blur_px;
      ++n;
    }
    ASSERT_GT(n, 0) << "blur " << blur;
    mean /= n;
    EXPECT_GT(mean, previous + 0.1) << "blur " << blur;
    // Fitted spread ~ sqrt(lens blur^2 + pixel box variance 1/12). Below ~0.8 px the renderer's
    // discrete Gaussian kernel is narrower than its nominal sigma, so compare only above.
    // Above ~1.2 px on these 5.6 px cells the usable band is narrower than the edge spread and
    // the fit sees the data bits: still monotone, no longer the true sigma.
    if (blur >= 0.8 && blur <= 1.2) {
      const double expected = std::sqrt(blur * blur + 1.0 / 12.0);
      EXPECT_NEAR(mean, expected, 0.05 * expected) << "blur " << blur;
    }
    previous = mean;
  }
}

// An axis-aligned edge puts every sample at the same sub-pixel phase, so any mismatch between
// the fit's model and the image's profile shows as a bias that follows the phase ("pixel
// locking"), shared by every corner whose edges have that phase. The profile of a camera (a
// continuous Gaussian lens blur integrated over the pixel's box) fits without bias at every
// phase; the fitted spread is sqrt(sigma^2 + 1/12).
TEST(EdgeFit, UnbiasedAtEverySubPixelPhaseOfAPixelIntegratedGaussianEdge) {
  const double dark = 20.0, bright = 220.0;
  const auto cdf = [](double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); };
  const auto pdf = [](double x) { return std::exp(-0.5 * x * x) / std::sqrt(2.0 * M_PI); };
  for (double sigma : {0.5, 0.8, 1.2}) {
    // Integral over [lo, hi] of Phi((t - x0) / sigma) dt: the pixel's box.
    const auto box = [&](double lo, double hi, double x0) {
      const auto F = [&](double t) {
        const double z = (t - x0) / sigma;
        return (t - x0) * cdf(z) + sigma * pdf(z);
      };
      return F(hi) - F(lo);
    };
    for (int k = 0; k < 10; ++k) {
      const double x0 = 11.0 + 0.1 * k;
      std::vector<rv::EdgeSample> samples;
      for (int y = 0; y < 16; ++y)
        for (int x = 7; x < 17; ++x)
          samples.push_back(
              {Eigen::Vector2d(x, y), dark + (bright - dark) * box(x - 0.5, x + 0.5, x0)});
      const auto fit = rv::fit_edge_line(samples, {x0 + 0.3, 0.0}, {x0 + 0.3, 15.0});
      ASSERT_TRUE(fit.has_value()) << "sigma " << sigma << " x0 " << x0;
      EXPECT_NEAR(std::abs(fit->normal.x()), 1.0, 1e-9);
      // Renderer-style blur applied after area sampling (cv::GaussianBlur on the pixel grid)
      // gives up to 0.018 px here at sigma 0.8 (bench_corner_bias --edge-phase 1).
      EXPECT_NEAR(fit->point().x(), x0, 2e-3) << "sigma " << sigma << " x0 " << x0;
      EXPECT_NEAR(fit->blur_sigma, std::sqrt(sigma * sigma + 1.0 / 12.0), 0.02) << sigma;
    }
  }
}

// Vignetting and uneven lighting multiply the image by a gain that changes across an edge. A
// step model with constant levels turns a gain ramp ALONG the edge into a rotation of the
// fitted line (the brighter end looks like more bright paper): at the demo's vignetting
// (relative gain slope ~2e-4 / px at mid radius) the corners of a 60 px tag edge moved by
// ~0.01 px, in the pattern of a tag's perspective taper, and the calibrated focal length came
// out ~1 sigma short (bench_intrinsics_bias). The fit models the gain as linear over
// the edge, so the line stays where it is.
TEST(EdgeFit, UnbiasedUnderAGainRampAlongAndAcrossTheEdge) {
  const double dark = 20.0, bright = 220.0, sigma = 0.8;
  const auto cdf = [](double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); };
  const auto pdf = [](double x) { return std::exp(-0.5 * x * x) / std::sqrt(2.0 * M_PI); };
  const auto box = [&](double lo, double hi, double x0) {
    const auto F = [&](double t) {
      const double z = (t - x0) / sigma;
      return (t - x0) * cdf(z) + sigma * pdf(z);
    };
    return F(hi) - F(lo);
  };
  for (bool curved : {false, true}) {
    for (const Eigen::Vector2d& gain :
         {Eigen::Vector2d(0.0, 3e-4), Eigen::Vector2d(0.0, -3e-4), Eigen::Vector2d(3e-4, 2e-4)}) {
      const double x0 = 11.37;  // a vertical edge x = x0, dark left, 60 px long
      std::vector<rv::EdgeSample> samples;
      for (int y = 0; y < 60; ++y)
        for (int x = 6; x < 17; ++x) {
          const double g = 1.0 + gain.x() * (x - 11.0) + gain.y() * (y - 30.0);
          samples.push_back(
              {Eigen::Vector2d(x, y), g * (dark + (bright - dark) * box(x - 0.5, x + 0.5, x0))});
        }
      const auto fit = rv::fit_edge_line(samples, {x0 + 0.3, 0.0}, {x0 - 0.3, 59.0}, 1.0, curved);
      ASSERT_TRUE(fit.has_value());
      // Where the fitted edge crosses the first and last rows (the corners' lever arm).
      std::array<double, 2> at{};
      for (int end = 0; end < 2; ++end) {
        rv::EdgeLineFit row;
        row.origin = Eigen::Vector2d(0.0, end == 0 ? 0.0 : 59.0);
        row.normal = Eigen::Vector2d(0.0, 1.0);
        const auto p = rv::intersect_lines(*fit, row);
        ASSERT_TRUE(p.has_value());
        at[static_cast<size_t>(end)] = p->x();
      }
      // Before the gain was modelled, a 3e-4 / px ramp along the edge turned the line by
      // 5e-4 rad: 0.016 px at either end, in opposite directions.
      EXPECT_NEAR(at[0], at[1], 3e-4) << "gain " << gain.transpose() << " curved " << curved;
      // A ramp across the edge (not modelled: it moves the line by ~slope * sigma^2 only, the
      // same at both ends) shifts it by about 1 mpx here.
      const double tolerance = gain.x() == 0.0 ? 3e-4 : 2e-3;
      for (double x : at)
        EXPECT_NEAR(x, x0, tolerance) << "gain " << gain.transpose() << " curved " << curved;
    }
  }
}

// The noise estimate, against Gaussian noise of known sigma added and rounded to whole DN: on a
// flat grey image it is the noise's alone (3 %); on rendered tag views (edges, blurred
// transitions, a flat background) the edges' pairs lift the median by up to ~8 % at low noise,
// which the 8-sigma threshold built on it does not notice (10 %).
TEST(PixelNoise, RecoversTheSigmaOfTheNoiseAddedToAScene) {
  Scene scene;
  for (const double sigma : {1.0, 2.0, 4.0, 8.0}) {
    cv::Mat noise(480, 640, CV_64FC1);
    cv::RNG rng(11);
    rng.fill(noise, cv::RNG::NORMAL, 100.0, sigma);
    cv::Mat flat;
    noise.convertTo(flat, CV_8UC1);  // rounds to the nearest DN
    EXPECT_NEAR(rv::pixel_noise_sigma(flat), sigma, 0.03 * sigma) << "flat, sigma " << sigma;
    std::vector<rt::SyntheticTag> truth;
    const cv::Mat image = scene.render(30.0, 0.8, sigma, 7, &truth);
    EXPECT_NEAR(rv::pixel_noise_sigma(image), sigma, 0.10 * sigma) << "tags, sigma " << sigma;
  }
  std::vector<rt::SyntheticTag> truth;
  EXPECT_LT(rv::pixel_noise_sigma(scene.render(30.0, 0.8, 0.0, 7, &truth)), 0.3);
  EXPECT_EQ(rv::pixel_noise_sigma(cv::Mat(20, 1, CV_8UC1, cv::Scalar(9))), 0.0);
}

TEST(PixelNoise, ThresholdIsEightSigmaBetweenTheLibraryDefaultAndTheKeptContrast) {
  EXPECT_EQ(rv::min_white_black_diff_for(0.0, 20.0), 5);
  EXPECT_EQ(rv::min_white_black_diff_for(0.5, 20.0), 5);
  EXPECT_EQ(rv::min_white_black_diff_for(2.0, 20.0), 16);
  EXPECT_EQ(rv::min_white_black_diff_for(3.0, 20.0), 24);
  EXPECT_EQ(rv::min_white_black_diff_for(10.0, 20.0), 40);
  EXPECT_EQ(rv::min_white_black_diff_for(10.0, 1.0), 5);
}

// The threshold taken from the image's noise only spares the quad search the noise: every tag
// the library's fixed default (5 DN) finds is found, with the same corners, down to tags of
// 60 DN contrast (a decision margin near the 20 kept).
TEST(AprilTagDetector, NoiseAdaptiveThresholdFindsWhatTheLibraryDefaultFinds) {
  Scene scene;
  rv::AprilTagDetectorOptions fixed;
  fixed.min_white_black_diff = 5;
  rv::AprilTagDetector by_default(fixed);
  rv::AprilTagDetector adaptive;
  fixed.min_white_black_diff = 110;  // above 60 DN of contrast and its noise
  rv::AprilTagDetector too_high(fixed);
  int tags = 0;
  for (const double contrast : {200.0, 60.0})
    for (const double noise : {2.0, 4.0})
      for (const double tilt : {0.0, 40.0, 60.0}) {
        rt::SyntheticImageOptions look;
        look.black = 120.0 - contrast / 2;
        look.white = 120.0 + contrast / 2;
        std::vector<rt::SyntheticTag> truth;
        const cv::Mat image = scene.render(tilt, 0.8, noise, 3, &truth, 319.5, 255.5, look);
        // The case is one where the thresholds differ.
        ASSERT_GE(rv::min_white_black_diff_for(rv::pixel_noise_sigma(image), 20.0), 15);
        const auto a = by_default.detect(image);
        const auto b = adaptive.detect(image);
        ASSERT_EQ(a.size(), b.size())
            << "contrast " << contrast << " noise " << noise << " tilt " << tilt;
        for (std::size_t k = 0; k < a.size(); ++k) {
          EXPECT_EQ(a[k].id, b[k].id);
          for (std::size_t c = 0; c < 4; ++c) EXPECT_EQ(a[k].corners[c], b[k].corners[c]);
        }
        tags += static_cast<int>(b.size());
        // A threshold above the contrast loses the tags: the comparison can tell.
        if (contrast < 70.0) {
          EXPECT_LT(too_high.detect(image).size(), b.size());
        }
      }
  EXPECT_GE(tags, 12 * 12 - 8);  // nearly all of the 12 tags of every view
}

TEST(AprilTagDetector, RejectsWrongImageTypeAndBadOptions) {
  rv::AprilTagDetector detector;
  EXPECT_THROW(detector.detect(cv::Mat()), std::invalid_argument);
  EXPECT_THROW(detector.detect(cv::Mat(50, 50, CV_16UC1, cv::Scalar(0))), std::invalid_argument);
  EXPECT_THROW(detector.detect(cv::Mat(50, 50, CV_8UC3, cv::Scalar(0))), std::invalid_argument);
  rv::AprilTagDetectorOptions bad;
  bad.family = "tag99h99";
  EXPECT_THROW(rv::AprilTagDetector{bad}, std::invalid_argument);
  bad = {};
  bad.quad_decimate = 0.5f;
  EXPECT_THROW(rv::AprilTagDetector{bad}, std::invalid_argument);
  bad = {};
  bad.min_white_black_diff = -1;
  EXPECT_THROW(rv::AprilTagDetector{bad}, std::invalid_argument);
  EXPECT_THROW((void)rv::pixel_noise_sigma(cv::Mat(50, 50, CV_8UC3, cv::Scalar(0))),
               std::invalid_argument);
  // A blank image is valid input with no tags in it.
  EXPECT_TRUE(detector.detect(cv::Mat(64, 64, CV_8UC1, cv::Scalar(128))).empty());
}

// Upstream AprilTag's own test photographs: with quad_decimate 1 and refine_edges off the library
// must reproduce the expected corners (AprilTag's convention) once our -0.5 shift is undone.
TEST(AprilTagDetector, UpstreamNasaPhotographs) {
  const std::filesystem::path dir =
      std::filesystem::path(ROBOCAL_SHARED_DATA_DIR) / "real" / "apriltag_nasa";
  SKIP_OR_FAIL_WITHOUT_REAL_DATA(dir);
  rv::AprilTagDetectorOptions opt;
  opt.quad_decimate = 1.0f;
  opt.refine_edges = false;
  opt.subpixel_refine = false;
  opt.max_hamming = 2;
  opt.min_decision_margin = 0.0;
  rv::AprilTagDetector detector(opt);
  // The refinement is checked in the production configuration: it starts from (and is compared
  // with) the library corners with refine_edges on; those with it off are biased by ~0.1-0.3 px
  // on sharp tags (vision.md) and, on a 42 px tag of the third photograph, lie 0.7 px from them.
  rv::AprilTagDetectorOptions refined_opt = opt;
  refined_opt.subpixel_refine = true;
  refined_opt.refine_edges = true;
  rv::AprilTagDetector refined_detector(refined_opt);
  int expected_total = 0;
  int matched_total = 0;
  int refined_total = 0;
  int large_total = 0;  // tags with a border cell of >= 3.75 px
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".jpg") continue;
    const cv::Mat img = cv::imread(entry.path().string(), cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(img.empty()) << entry.path();
    const auto found = detector.detect(img);
    const auto refined = refined_detector.detect(img);
    std::ifstream txt(std::filesystem::path(entry.path()).replace_extension(".txt"));
    std::string line;
    while (std::getline(txt, line)) {
      // "id, (x y), (x y), (x y), (x y)"
      for (char& ch : line)
        if (ch == ',' || ch == '(' || ch == ')') ch = ' ';
      std::istringstream fields(line);
      std::vector<double> v;
      for (double x = 0.0; fields >> x;) v.push_back(x);
      if (v.size() != 9) continue;
      ++expected_total;
      std::array<Eigen::Vector2d, 4> want;
      for (size_t k = 0; k < 4; ++k) want[k] = {v[1 + 2 * k], v[2 + 2 * k]};
      for (const auto& d : found) {
        double worst = 0.0;
        for (size_t k = 0; k < 4; ++k) {
          const Eigen::Vector2d lib = d.library_corners[k] - Eigen::Vector2d(-0.5, -0.5);
          worst = std::max(worst, (lib - want[k]).norm());
        }
        if (worst < 0.15) ++matched_total;
      }
    }
    // No ground truth here (the .txt corners are the library's own, refine_edges off, which is
    // biased by ~0.1-0.3 px on sharp tags and more on these 12-35 px JPEG tags): refined corners
    // are only checked for gross failure, within 1 px of the library's.
    for (const auto& d : refined) {
      const double side = (d.library_corners[0] - d.library_corners[2]).norm() / std::sqrt(2.0);
      if (side >= 30.0) ++large_total;
      if (!d.refined) continue;
      ++refined_total;
      for (size_t k = 0; k < 4; ++k) {
        EXPECT_LT((d.corners[k] - d.library_corners[k]).norm(), 1.0)
            << entry.path() << " tag " << d.id;
      }
    }
  }
  EXPECT_EQ(expected_total, 47);
  EXPECT_EQ(matched_total, expected_total);
  // Real, small (12-35 px), blurry JPEG tags: those with border cells under 3 px are left to the
  // library; the larger ones must be refined.
  EXPECT_GE(refined_total, large_total);
  EXPECT_GT(large_total, 0);
}
