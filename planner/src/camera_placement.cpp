// Camera placement for a working volume (see camera_placement.hpp).
#include "robocal/planner/camera_placement.hpp"

#include "robocal/planner/feasibility.hpp"
#include "robocal/planner/plan.hpp"
#include "robocal/planner/task_sampling.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <optional>
#include <random>
#include <sstream>
#include <stdexcept>

namespace robocal::planner {
namespace {

// world_T_camera at `eye` looking at `at`, image up close to `up`.
Eigen::Isometry3d look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& at,
                          Eigen::Vector3d up) {
  const Eigen::Vector3d z = (at - eye).normalized();
  if (std::abs(z.dot(up.normalized())) > 0.99)
    up = std::abs(z.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d x = (-up).cross(z).normalized();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = z.cross(x);
  T.linear().col(2) = z;
  T.translation() = eye;
  return T;
}

// Greedy growth of a camera array from its first station (camera_placement.hpp). Each round
// ranks the candidate stations by the poses they would add seen by at least two cameras (quick
// test), measures the best few with the full test (occlusion by links and obstacles included)
// and adds the best of those, among candidates sharing a view with the array (one of their
// cameras and one already placed see the same pose: the rig's board views chain through it).
template <typename QuickCounts, typename FullCounts>
CameraPlacement grow_array(const CameraPlacement& first,
                           const std::vector<CameraPlacement>& stations,
                           const QuickCounts& quick_counts, const FullCounts& full_counts,
                           const PlacementOptions& options, int ncam) {
  CameraPlacement array = first;
  array.station_look_at = {first.look_at};
  array.cameras_per_station = ncam;
  array.min_cameras = 2;
  std::vector<int> quick = quick_counts(array.world_T_camera);
  std::vector<int> full = full_counts(array.world_T_camera);
  const std::size_t poses = full.size();
  auto covered = [](const std::vector<int>& now, const std::vector<int>& add) {
    std::ptrdiff_t n = 0;
    for (std::size_t b = 0; b < now.size(); ++b) n += now[b] + add[b] >= 2 ? 1 : 0;
    return n;
  };
  const std::vector<int> none(poses, 0);
  std::vector<std::vector<int>> station_quick;
  station_quick.reserve(stations.size());
  for (const CameraPlacement& t : stations) station_quick.push_back(quick_counts(t.world_T_camera));
  const auto min_gain = std::max<std::ptrdiff_t>(1, static_cast<std::ptrdiff_t>(0.02 * poses));
  while (static_cast<int>(array.world_T_camera.size()) + ncam <= options.max_cameras &&
         static_cast<double>(covered(full, none)) <
             options.array_coverage * static_cast<double>(poses)) {
    // Quick ranking of the candidates that share a view with the array.
    std::vector<std::pair<std::ptrdiff_t, std::size_t>> ranked;
    const auto quick_now = covered(quick, none);
    for (std::size_t t = 0; t < stations.size(); ++t) {
      std::size_t shared = 0;
      for (std::size_t b = 0; b < poses; ++b)
        shared += quick[b] > 0 && station_quick[t][b] > 0 ? 1 : 0;
      if (shared < 3) continue;
      const auto gain = covered(quick, station_quick[t]) - quick_now;
      if (gain >= min_gain) ranked.emplace_back(gain, t);
    }
    std::stable_sort(ranked.begin(), ranked.end(),
                     [](const auto& a, const auto& b) { return a.first > b.first; });
    // The best few under the full test.
    std::ptrdiff_t best_gain = 0;
    std::size_t best = stations.size();
    std::vector<int> best_full;
    const auto full_now = covered(full, none);
    for (std::size_t k = 0; k < std::min<std::size_t>(6, ranked.size()); ++k) {
      std::vector<int> add = full_counts(stations[ranked[k].second].world_T_camera);
      const auto gain = covered(full, add) - full_now;
      if (gain > best_gain) {
        best_gain = gain;
        best = ranked[k].second;
        best_full = std::move(add);
      }
    }
    if (best == stations.size() || best_gain < min_gain) break;
    for (const Eigen::Isometry3d& wc : stations[best].world_T_camera)
      array.world_T_camera.push_back(wc);
    for (std::size_t b = 0; b < poses; ++b) {
      full[b] += best_full[b];
      quick[b] += station_quick[best][b];
    }
    array.station_look_at.push_back(stations[best].look_at);
  }
  array.coverage = static_cast<double>(covered(full, none)) / static_cast<double>(poses);
  return array;
}

// The cell's feasibility test without the tolerance margin of the reach edge (feasibility test
// 5): placement asks what the cameras see of the working volume, where the real robot reaches
// is the plan's concern, and the drawn robots would only cost time here.
FeasibilityOptions placement_feasibility(const Cell& cell) {
  FeasibilityOptions o = feasibility_options_from_cell(cell);
  o.tolerance_draws = 0;
  return o;
}

}  // namespace

Cell with_cameras(const Cell& cell, const CameraPlacement& placement) {
  Cell out = cell;
  const CellCamera templ = cell.cameras.empty() ? CellCamera{} : cell.cameras.front();
  out.cameras.clear();
  for (std::size_t i = 0; i < placement.world_T_camera.size(); ++i) {
    CellCamera c = i < cell.cameras.size() ? cell.cameras[i] : templ;
    if (i >= cell.cameras.size()) c.name = "camera" + std::to_string(i + 1);
    c.world_T_camera = placement.world_T_camera[i];
    c.pose_known = true;
    c.pose_uncertainty = 0.0;
    out.cameras.push_back(c);
  }
  if (placement.min_cameras > 0) out.visibility.min_cameras = placement.min_cameras;
  // Visibility requirements naming cameras that no longer exist fall back to "all".
  for (const std::string& n : out.visibility.cameras)
    if (out.camera_index(n) < 0) {
      out.visibility.cameras.clear();
      break;
    }
  return out;
}

namespace {

// The target board's outline (its four corners in the board frame) and the figures placement
// derives from it.
struct BoardShape {
  std::vector<Eigen::Vector3d> outline;
  Eigen::Vector3d mid = Eigen::Vector3d::Zero();
  double half_diag = 0.0;
  double short_side = 0.0;
};

BoardShape board_shape(const vision::TargetBoard& board) {
  BoardShape b;
  b.outline = board_outline(board);
  for (const Eigen::Vector3d& p : b.outline) b.mid += p / 4.0;
  b.half_diag = 0.5 * (b.outline[2] - b.outline[0]).norm();
  b.short_side =
      std::min((b.outline[1] - b.outline[0]).norm(), (b.outline[3] - b.outline[0]).norm());
  return b;
}

// Reachable, collision-free poses inside the workspace (visibility not asked), at most
// options.samples of them: the readings, the board centre, the board's face direction and pose.
struct SampledPoses {
  std::vector<Eigen::VectorXd> configs;
  std::vector<Eigen::Vector3d> centres, normals;
  std::vector<Eigen::Isometry3d> boards;  // for the quick coverage score
};

SampledPoses sample_reachable_poses(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                    const Cell& cell, int frame, const PlacementOptions& options,
                                    const Eigen::Vector3d& board_mid) {
  FeasibilityOptions no_sight = placement_feasibility(cell);
  no_sight.check_visibility = false;
  const FeasibilityChecker reach(model, params, cell, frame, no_sight);
  std::mt19937 rng(options.seed);
  SampledPoses poses;
  for (const Candidate& cand :
       reach.sample(static_cast<std::size_t>(10 * options.samples), rng, nullptr)) {
    if (!cand.feasible()) continue;
    if (static_cast<int>(poses.configs.size()) >= options.samples) break;
    poses.configs.push_back(cand.readings);
    poses.centres.emplace_back(cand.world_T_board * board_mid);
    poses.normals.emplace_back(-cand.world_T_board.linear().col(2));
    poses.boards.push_back(cand.world_T_board);
  }
  return poses;
}

// Quick visibility of the sampled boards from one camera: the outline inside the image
// (border), within the maximum incidence and at least min_image_size (occlusion is left to the
// full test of the chosen placement). A robot whose joints turn its target (fewer than six
// actuators, task_sampling.hpp: the wire robot's platform) has its board turned towards the
// camera before the test, as its planned poses will be; the full test aims it the same way.
class QuickVisibility {
 public:
  QuickVisibility(const Cell& cell, const std::vector<Eigen::Isometry3d>& boards,
                  const BoardShape& board, bool turned)
      : cell_(cell),
        cam_(cell.cameras.front().model),
        boards_(boards),
        board_(board),
        turned_(turned) {}

  // Per sampled board: whether the camera at `wc` (world_T_camera) sees it.
  [[nodiscard]] std::vector<char> sees(const Eigen::Isometry3d& wc) const {
    const Eigen::Vector3d& board_mid = board_.mid;
    std::vector<char> sees(boards_.size(), 0);
    const Eigen::Isometry3d cw = wc.inverse();
    for (std::size_t b = 0; b < boards_.size(); ++b) {
      Eigen::Isometry3d board = boards_[b];
      if (turned_) {
        const Eigen::Vector3d centre = board * board_mid;
        const Eigen::Vector3d face = -board.linear().col(2);
        const Eigen::Matrix3d turn =
            Eigen::Quaterniond::FromTwoVectors(face, wc.translation() - centre).toRotationMatrix();
        board.linear() = turn * board.linear();
        board.translation() = centre - board.linear() * board_mid;
      }
      const Eigen::Isometry3d cb = cw * board;
      const Eigen::Vector3d centre = cb * board_mid;
      const Eigen::Vector3d face = -cb.linear().col(2);
      if (std::acos(std::clamp(face.dot(-centre.normalized()), -1.0, 1.0)) >
          cell_.visibility.max_incidence)
        continue;
      std::vector<Eigen::Vector2d> px;
      for (const Eigen::Vector3d& p : board_.outline) {
        const auto q = vision::project(cam_, cb * p);
        if (!q || !vision::in_image(cam_, *q, cell_.margins.image_border)) break;
        px.push_back(*q);
      }
      sees[b] = px.size() == 4 && std::min((px[1] - px[0]).norm(), (px[3] - px[0]).norm()) >=
                                      cell_.visibility.min_image_size;
    }
    return sees;
  }

  // Per sampled board: how many of the cameras see it.
  [[nodiscard]] std::vector<int> counts(
      const std::vector<Eigen::Isometry3d>& world_T_camera) const {
    std::vector<int> count(boards_.size(), 0);
    for (const Eigen::Isometry3d& wc : world_T_camera) {
      const std::vector<char> seen = sees(wc);
      for (std::size_t b = 0; b < boards_.size(); ++b) count[b] += seen[b];
    }
    return count;
  }

  // The fraction of sampled boards every camera sees.
  [[nodiscard]] double coverage(const std::vector<Eigen::Isometry3d>& world_T_camera) const {
    const std::vector<int> count = counts(world_T_camera);
    const auto all =
        std::count(count.begin(), count.end(), static_cast<int>(world_T_camera.size()));
    return static_cast<double>(all) / static_cast<double>(boards_.size());
  }

 private:
  const Cell& cell_;
  const vision::CameraModel& cam_;
  const std::vector<Eigen::Isometry3d>& boards_;
  const BoardShape& board_;
  bool turned_;
};

// What every station shares: its number of cameras and their tilt (half the triangulation
// angle when there are several), the narrower half field of view, and the distance keeping the
// target's image at min_image_size (10 % margin).
struct StationShape {
  int ncam = 1;
  double tilt = 0.0;
  double half_fov = 0.0;
  double size_distance = 0.0;
};

StationShape station_shape(const Cell& cell, const PlacementOptions& options, double short_side) {
  const vision::CameraModel& cam = cell.cameras.front().model;
  const double fx = cam.params[0], fy = cam.params[1];
  StationShape s;
  s.half_fov = std::min(std::atan(0.5 * cam.width / fx), std::atan(0.5 * cam.height / fy));
  s.ncam = std::max(1, options.cameras);
  s.tilt = s.ncam > 1 ? 0.5 * options.triangulation_angle : 0.0;
  s.size_distance = cell.visibility.min_image_size > 0
                        ? std::min(fx, fy) * short_side / (1.1 * cell.visibility.min_image_size)
                        : 1e300;
  return s;
}

// A station of ncam cameras at `distance` from `c` on a circle around the direction `n`, each
// tilted by half the triangulation angle.
CameraPlacement station(const StationShape& shape, const Eigen::Vector3d& c,
                        const Eigen::Vector3d& n, const Eigen::Vector3d& e1,
                        const Eigen::Vector3d& e2, const Eigen::Vector3d& up, double distance) {
  const int ncam = shape.ncam;
  const double tilt = shape.tilt;
  CameraPlacement pl;
  pl.look_at = c;
  pl.view_direction = n;
  for (int i = 0; i < ncam; ++i) {
    const double phi = 2 * M_PI * i / ncam;
    const Eigen::Vector3d dir =
        (std::cos(tilt) * n + std::sin(tilt) * (std::cos(phi) * e1 + std::sin(phi) * e2))
            .normalized();
    pl.world_T_camera.push_back(look_at(c + distance * dir, c, up));
  }
  pl.distance = distance;
  pl.baseline =
      ncam > 1 ? (pl.world_T_camera[0].translation() - pl.world_T_camera[1].translation()).norm()
               : 0.0;
  return pl;
}

// Candidate viewing directions: the mean face direction (one side for a level board, as on a
// Delta), then the face directions of a spread of sampled poses (a serial arm's board faces
// every way; a camera pair sees one side of its range).
std::vector<Eigen::Vector3d> viewing_directions(const std::vector<Eigen::Vector3d>& normals) {
  Eigen::Vector3d mean_n = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& v : normals) mean_n += v;
  std::vector<Eigen::Vector3d> directions(17, Eigen::Vector3d::UnitZ());
  if (mean_n.norm() > 1e-6 * static_cast<double>(normals.size()))
    directions[0] = mean_n.normalized();
  for (std::size_t k = 1; k < directions.size(); ++k)
    directions[k] = normals[(k - 1) * normals.size() / 16].normalized();
  return directions;
}

// The target centres of the sampled poses whose board faces within 40 deg of `n`.
// (A target the joints turn can face any of them.)
std::vector<Eigen::Vector3d> facing_centres(const SampledPoses& poses, const Eigen::Vector3d& n,
                                            bool turned) {
  std::vector<Eigen::Vector3d> facing;
  facing.reserve(poses.centres.size());
  for (std::size_t i = 0; i < poses.centres.size(); ++i)
    if (turned || poses.normals[i].normalized().dot(n) >= std::cos(40.0 * M_PI / 180.0))
      facing.push_back(poses.centres[i]);
  return facing;
}

// Every placement tried, with its quick coverage. For each viewing direction, the look-at point
// and radius come from the poses whose board faces that way (within 40 deg); stops early once a
// placement sees nearly every sampled board.
std::vector<CameraPlacement> try_placements(const SampledPoses& poses, bool turned,
                                            const StationShape& shape, double half_diag,
                                            const QuickVisibility& quick) {
  std::vector<CameraPlacement> tried;
  double best_quick = -1.0;
  for (const Eigen::Vector3d& n : viewing_directions(poses.normals)) {
    const std::vector<Eigen::Vector3d> facing = facing_centres(poses, n, turned);
    if (facing.size() < std::max<std::size_t>(5, poses.centres.size() / 20)) continue;
    Eigen::Vector3d mean_c = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& p : facing) mean_c += p;
    mean_c /= static_cast<double>(facing.size());
    // Look-at points: the facing poses' mean, then 8 of them spread over the list (a working
    // volume larger than the view, or a ring around an arm's base, is seen in part).
    std::vector<Eigen::Vector3d> look(9, mean_c);
    for (std::size_t k = 1; k < look.size(); ++k) look[k] = facing[(k - 1) * facing.size() / 8];
    const Eigen::Vector3d e1 = n.unitOrthogonal();
    const Eigen::Vector3d e2 = n.cross(e1);
    const Eigen::Vector3d up = std::abs(n.z()) > 0.9 ? e2 : Eigen::Vector3d::UnitZ();
    for (std::size_t li = 0; li < look.size(); ++li) {
      const Eigen::Vector3d& c = look[li];
      double radius = half_diag;
      for (const Eigen::Vector3d& p : facing) radius = std::max(radius, (p - c).norm() + half_diag);
      // Distance: the volume's sphere inside the narrower half field of view (15 % margin), but
      // no farther than keeps the target's image at min_image_size (10 % margin) on the far
      // side; from a look-at point inside a larger volume, up to where the target at that point
      // keeps min_image_size.
      const double fov_distance = radius / std::sin(0.85 * shape.half_fov);
      const double size_distance = shape.size_distance - radius;
      const double top =
          li == 0 ? std::min(1.6 * fov_distance, std::max(size_distance, 0.3 * fov_distance))
                  : std::min(1.6 * fov_distance, shape.size_distance);
      // From 60 % of the field-of-view distance (the mean) or 40 % of the top (a point) up to
      // the top; keep the best coverage, the nearer on ties (bigger images).
      const double first = li == 0 ? 0.6 * fov_distance : 0.4 * top;
      for (int k = 0; k <= 6; ++k) {
        const double distance = li == 0 ? std::min(top, fov_distance * (0.6 + 0.1 * 1.67 * k))
                                        : std::min(top, first + (top - first) * k / 6.0);
        CameraPlacement pl = station(shape, c, n, e1, e2, up, distance);
        pl.volume_radius = radius;
        pl.coverage = quick.coverage(pl.world_T_camera);
        best_quick = std::max(best_quick, pl.coverage);
        tried.push_back(pl);
        if (distance >= top) break;
      }
    }
    if (best_quick >= 0.999) break;
  }
  return tried;
}

// The 6 best tried placements by quick coverage (the nearer first on ties: bigger images) under
// the full test (all corners, occlusion by links and obstacles): the best of them wins. Sorts
// `tried` in that order.
CameraPlacement best_under_full_test(std::vector<CameraPlacement>& tried,
                                     const calib::Mechanism& model, const Eigen::VectorXd& params,
                                     const Cell& cell, int frame,
                                     const std::vector<Eigen::VectorXd>& configs, bool turned) {
  std::stable_sort(tried.begin(), tried.end(),
                   [](const CameraPlacement& a, const CameraPlacement& b) {
                     return a.coverage > b.coverage + 1e-9 ||
                            (std::abs(a.coverage - b.coverage) <= 1e-9 && a.distance < b.distance);
                   });
  CameraPlacement best;
  best.coverage = -1;
  for (std::size_t k = 0; k < std::min<std::size_t>(6, tried.size()); ++k) {
    CameraPlacement pl = tried[k];
    const Cell placed = with_cameras(cell, pl);
    const FeasibilityChecker checker(model, params, placed, frame, placement_feasibility(placed));
    std::size_t seen = 0;
    for (const Eigen::VectorXd& x : configs)
      seen +=
          (turned ? evaluate_turned_towards_cameras(checker, x) : checker.evaluate(x)).feasible()
              ? 1
              : 0;
    pl.coverage = static_cast<double>(seen) / static_cast<double>(configs.size());
    if (pl.coverage > best.coverage + 1e-9) best = pl;
  }
  return best;
}

// The placement in words, with millimetre-rounded figures: a direction read off a drawing, not
// the solver's last bits.
std::string placement_summary(const CameraPlacement& out, int ncam, std::size_t poses) {
  const Eigen::Vector3d c = out.look_at, n = out.view_direction;
  const auto xyz = [](const Eigen::Vector3d& v) {
    const auto at = [&](int i) { return std::abs(v[i]) < 5e-4 ? 0.0 : v[i]; };  // no "-0.000"
    std::array<char, 96> text{};
    std::snprintf(text.data(), text.size(), "[%.3f, %.3f, %.3f]", at(0), at(1), at(2));
    return std::string(text.data());
  };
  std::ostringstream s;
  s << ncam << " camera(s) " << std::fixed << std::setprecision(3) << out.distance
    << " m from the point they look at (" << xyz(c) << " m), looking along " << xyz(-n) << ", "
    << out.baseline << " m apart; they see the target at " << std::lround(100 * out.coverage)
    << " % of " << poses << " reachable sampled poses";
  return s.str();
}

// Per sampled pose, how many of `cameras` see the target under the full test.
std::vector<int> full_counts(const calib::Mechanism& model, const Eigen::VectorXd& params,
                             const Cell& cell, int frame,
                             const std::vector<Eigen::VectorXd>& configs, bool turned,
                             const std::vector<Eigen::Isometry3d>& cameras) {
  CameraPlacement p;
  p.world_T_camera = cameras;
  const Cell placed = with_cameras(cell, p);
  FeasibilityOptions opts = placement_feasibility(placed);
  opts.check_visibility = false;  // per-camera verdicts only
  const FeasibilityChecker checker(model, params, placed, frame, opts);
  std::vector<int> count(configs.size(), 0);
  for (std::size_t i = 0; i < configs.size(); ++i) {
    const Candidate cand = turned ? evaluate_turned_towards_cameras(checker, configs[i])
                                  : checker.evaluate(configs[i]);
    if (!cand.feasible()) continue;
    for (const CameraView& v : cand.views) count[i] += v.visible ? 1 : 0;
  }
  return count;
}

// An array of stations grown from the first one `out` (grow_array), when it sees more than the
// one station does; none otherwise. Candidate stations: the tried placements, and pairs looking
// along the first station's direction at 32 points spread over the poses facing that way, from
// the distance keeping the target's image at min_image_size and from two nearer ones.
std::optional<CameraPlacement> propose_array(
    const CameraPlacement& out, const std::vector<CameraPlacement>& tried,
    const calib::Mechanism& model, const Eigen::VectorXd& params, const Cell& cell, int frame,
    const PlacementOptions& options, const SampledPoses& poses, bool turned,
    const StationShape& shape, const QuickVisibility& quick) {
  const int ncam = shape.ncam;
  const Eigen::Vector3d n = out.view_direction;
  std::vector<CameraPlacement> stations = tried;
  {
    const Eigen::Vector3d e1 = n.unitOrthogonal();
    const Eigen::Vector3d e2 = n.cross(e1);
    const Eigen::Vector3d up = std::abs(n.z()) > 0.9 ? e2 : Eigen::Vector3d::UnitZ();
    const std::vector<Eigen::Vector3d> facing = facing_centres(poses, n, turned);
    const double far = std::min(out.distance, shape.size_distance);
    for (std::size_t k = 0; k < 32 && !facing.empty(); ++k)
      for (const double f : {1.0, 0.8, 0.6})
        stations.push_back(station(shape, facing[k * facing.size() / 32], n, e1, e2, up, f * far));
  }
  const auto quick_counts = [&](const std::vector<Eigen::Isometry3d>& world_T_camera) {
    return quick.counts(world_T_camera);
  };
  const auto full = [&](const std::vector<Eigen::Isometry3d>& cameras) {
    return full_counts(model, params, cell, frame, poses.configs, turned, cameras);
  };
  CameraPlacement array = grow_array(out, stations, quick_counts, full, options, ncam);
  if (!(array.station_look_at.size() > 1 && array.coverage > out.coverage)) return std::nullopt;
  std::ostringstream a;
  a << array.world_T_camera.size() << " cameras in " << array.station_look_at.size()
    << " stations of " << ncam << " (one pair sees the target at only "
    << std::lround(100 * out.coverage) << " % of " << poses.configs.size()
    << " reachable sampled poses; two cameras of the array see it at "
    << std::lround(100 * array.coverage) << " %); stations look at";
  for (std::size_t k = 0; k < array.station_look_at.size(); ++k)
    a << (k == 0 ? " (" : ", (") << array.station_look_at[k].transpose() << ")";
  a << ", first station " << out.distance << " m away, baseline " << out.baseline << " m";
  array.summary = a.str();
  return array;
}

}  // namespace

CameraPlacement propose_cameras(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                const Cell& cell, const PlacementOptions& options) {
  if (cell.cameras.empty())
    throw std::invalid_argument("camera placement needs one camera model (intrinsics)");
  const int frame = target_frame(model, cell);
  if (frame < 0) throw std::invalid_argument("the target's frame is not a body of the robot");
  const BoardShape board = board_shape(cell.target.board);
  const SampledPoses poses = sample_reachable_poses(model, params, cell, frame, options, board.mid);
  if (poses.configs.empty())
    throw std::invalid_argument("robot '" + model.name +
                                "' reaches no configuration inside the workspace");
  const StationShape shape = station_shape(cell, options, board.short_side);
  const bool turned = target_turned_by_joints(model, frame);
  const QuickVisibility quick(cell, poses.boards, board, turned);
  // Every placement tried, with its quick coverage; the best few are measured in full.
  std::vector<CameraPlacement> tried = try_placements(poses, turned, shape, board.half_diag, quick);
  const CameraPlacement best =
      best_under_full_test(tried, model, params, cell, frame, poses.configs, turned);
  if (tried.empty())
    throw std::invalid_argument("no viewing direction sees enough of robot '" + model.name +
                                "'s reachable poses");
  CameraPlacement out = best;
  out.summary = placement_summary(out, shape.ncam, poses.configs.size());
  if (options.max_cameras >= 2 * shape.ncam && shape.ncam >= 2 &&
      out.coverage < options.min_coverage) {
    if (auto array = propose_array(out, tried, model, params, cell, frame, options, poses, turned,
                                   shape, quick))
      return *array;
  }
  return out;
}

}  // namespace robocal::planner
