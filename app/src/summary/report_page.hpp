#pragma once
// The calibration report page (`robocal report`, results/report.html): one self-contained HTML
// file with inline SVG figures, no scripts and no network access. The stage (stages/report.cpp)
// gathers the figures into ReportData — numbers already computed by calib's statistics — and
// this file only lays them out; render_report_page is a pure function of its input.
#include "robocal/calib/residual_diagnostics.hpp"

#include <Eigen/Core>

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace robocal::app {

// Held-out (or fit) accuracy over one set of poses, metres.
struct ReportAccuracy {
  std::string label;  // e.g. "all held-out poses", "inside the measured region"
  std::size_t poses = 0;
  std::optional<double> nominal_rms, nominal_max;  // none: not known (no truth)
  double calibrated_rms = 0.0, calibrated_max = 0.0;
};

// A parameter as a person reads it: the robot file's words for it (`label`), and its name in the
// robot file and the JSON (`raw`), which the page keeps at hand as a tooltip.
struct ReportName {
  std::string label, raw;
};
// Text that names parameters: parts with an empty `raw` are plain text (in `label`).
using ReportSentence = std::vector<ReportName>;

// One identified parameter, in display units (mm, degrees, or a ratio).
struct ReportParameter {
  ReportName name;
  std::string unit;
  double nominal = 0.0, value = 0.0, change = 0.0;
  double ci95 = 0.0;                   // half-width of the 95 % interval of value
  std::vector<ReportName> stands_for;  // held parameters it cannot be told apart from
  bool strongly_correlated = false;
};

struct ReportCorrelation {
  ReportName first, second;
  double r = 0.0;
};

// Where one camera saw the board's corners and how well each pose's board fit reprojects.
struct ReportCamera {
  std::string name;
  int width = 0, height = 0;
  std::vector<Eigen::Vector2d> corners;       // detected corners, px (subsampled to bound size)
  std::vector<Eigen::Vector2d> pose_centres;  // centroid of each pose's corners, px
  std::vector<double> pose_rms_px;            // that pose's board-fit reprojection RMS, px
};

struct ReportDiagnostics {
  std::string source;  // e.g. "measured poses: measured minus calibrated model, vs position"
  calib::ResidualTrends trends;
};

struct ReportData {
  std::string session, robot, software;
  std::string verdict;  // one plain sentence at the top
  std::vector<ReportAccuracy> accuracy;
  std::string accuracy_note;

  // Per-pose errors (metres): before (nominal model; may be empty) and after calibration.
  std::string per_pose_source;
  std::vector<double> error_before, error_after;
  calib::Histogram histogram_before, histogram_after;  // counts over error in metres

  // The error map: grids of the after (and before) error over two projections of the workspace
  // (camera 0's frame), with the measured positions drawn on top.
  bool has_map = false;
  std::string map_source;  // which errors the map shows, e.g. "held-out poses"
  calib::ErrorGrid top_after, side_after, top_before, side_before;
  std::vector<Eigen::Vector2d> measured_top, measured_side;

  std::vector<ReportParameter> parameters;  // the identified ones
  std::string parameter_counts;             // how many were identified, held, fixed (a sentence)
  std::vector<ReportCorrelation> correlations;
  std::string held_counts;                     // how many are held at nominal, and how (a sentence)
  std::vector<ReportSentence> not_identified;  // why they are held
  std::vector<ReportSentence> identification_notes;  // what else the analysis says

  std::vector<ReportCamera> cameras;
  std::vector<ReportDiagnostics> diagnostics;
  std::vector<std::pair<std::string, double>> timings;  // stage, seconds
};

// The ids of the page's figures, in page order (the browser test checks each is present).
const std::vector<std::string>& report_figure_ids();

std::string render_report_page(const ReportData& data);

}  // namespace robocal::app
