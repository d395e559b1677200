#include "render/pattern_index.hpp"

#include <Eigen/LU>

namespace robocal::vision::detail {

namespace {

// Area and centroid of a simple polygon.
double polygon_moments(const Eigen::Vector2d* v, int n, Eigen::Vector2d* centroid) {
  double a2 = 0, cx = 0, cy = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d& p = v[i];
    const Eigen::Vector2d& r = v[(i + 1) % n];
    const double cross = p.x() * r.y() - r.x() * p.y();
    a2 += cross;
    cx += (p.x() + r.x()) * cross;
    cy += (p.y() + r.y()) * cross;
  }
  if (a2 == 0.0) {
    *centroid = v[0];
    return 0.0;
  }
  *centroid = Eigen::Vector2d(cx / (3 * a2), cy / (3 * a2));
  return 0.5 * std::abs(a2);
}

// Area of a convex polygon clipped to an axis-aligned rectangle (Sutherland-Hodgman).
double clipped_area(const std::array<Eigen::Vector2d, 4>& q, double rx0, double ry0, double rx1,
                    double ry1, Eigen::Vector2d* centroid) {
  Eigen::Vector2d buf_a[12], buf_b[12];
  int n = 4;
  for (int i = 0; i < 4; ++i) buf_a[i] = q[static_cast<size_t>(i)];
  Eigen::Vector2d* in = buf_a;
  Eigen::Vector2d* out = buf_b;
  for (int edge = 0; edge < 4 && n > 0; ++edge) {
    const int axis = edge % 2;  // 0: x, 1: y
    const bool keep_greater = edge < 2;
    const double bound = edge == 0 ? rx0 : edge == 1 ? ry0 : edge == 2 ? rx1 : ry1;
    auto inside = [&](const Eigen::Vector2d& p) {
      return keep_greater ? p[axis] >= bound : p[axis] <= bound;
    };
    int m = 0;
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector2d& a = in[i];
      const Eigen::Vector2d& b = in[(i + 1) % n];
      const bool ia = inside(a), ib = inside(b);
      if (ia) out[m++] = a;
      if (ia != ib) {
        const double t = (bound - a[axis]) / (b[axis] - a[axis]);
        out[m++] = a + t * (b - a);
      }
    }
    n = m;
    std::swap(in, out);
  }
  if (n < 3) {
    // Nothing left: still a defined centroid, the caller weights the (zero) area with it.
    *centroid = q[0];
    return 0.0;
  }
  return polygon_moments(in, n, centroid);
}

// The footprint's board area is not spread evenly over the pixel: under perspective the board
// area per image area (det of the pixel->board Jacobian) changes across the pixel. To first order
// it is the bilinear interpolation of its values at the four corners, so each clipped piece is
// weighted by 1/det at its centroid (a 60 degree tilt would otherwise shift edges by ~0.0005 px).
struct FootprintWeight {
  double det00, det10, det11, det01;
  Eigen::Vector2d centre;
  Eigen::Matrix2d st_of;  // board offset from the centre -> (s, t) offset, locally affine
  bool weighted;

  explicit FootprintWeight(const std::array<Eigen::Vector2d, 4>& q) {
    auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
      return a.x() * b.y() - a.y() * b.x();
    };
    det00 = cross(q[1] - q[0], q[3] - q[0]);
    det10 = cross(q[1] - q[0], q[2] - q[1]);
    det11 = cross(q[2] - q[3], q[2] - q[1]);
    det01 = cross(q[2] - q[3], q[3] - q[0]);
    centre = 0.25 * (q[0] + q[1] + q[2] + q[3]);
    st_of.col(0) = 0.5 * (q[1] + q[2] - q[0] - q[3]);
    st_of.col(1) = 0.5 * (q[2] + q[3] - q[0] - q[1]);
    weighted = std::abs(st_of.determinant()) > 0.0;
    if (weighted) st_of = st_of.inverse().eval();
    weighted = weighted && det00 * det10 > 0 && det00 * det11 > 0 && det00 * det01 > 0;
  }
  double operator()(const Eigen::Vector2d& p) const {
    const Eigen::Vector2d st = Eigen::Vector2d(0.5, 0.5) + st_of * (p - centre);
    const double s_ = std::clamp(st.x(), 0.0, 1.0), t_ = std::clamp(st.y(), 0.0, 1.0);
    return 1.0 / ((1 - s_) * (1 - t_) * det00 + s_ * (1 - t_) * det10 + s_ * t_ * det11 +
                  (1 - s_) * t_ * det01);
  }
};

}  // namespace

double PatternIndex::black_fraction(const std::array<Eigen::Vector2d, 4>& q) const {
  double bx0 = q[0].x(), bx1 = q[0].x(), by0 = q[0].y(), by1 = q[0].y();
  for (int i = 1; i < 4; ++i) {
    bx0 = std::min(bx0, q[static_cast<size_t>(i)].x());
    bx1 = std::max(bx1, q[static_cast<size_t>(i)].x());
    by0 = std::min(by0, q[static_cast<size_t>(i)].y());
    by1 = std::max(by1, q[static_cast<size_t>(i)].y());
  }
  // Candidate patches from the cells the bounding box touches (deduplicated).
  int cand[16];
  int n_cand = 0;
  bool overflow = false;
  const int ci0 = cell_x(bx0), ci1 = cell_x(bx1), cj0 = cell_y(by0), cj1 = cell_y(by1);
  for (int j = cj0; j <= cj1 && !overflow; ++j)
    for (int i = ci0; i <= ci1 && !overflow; ++i)
      for (int k : cells[static_cast<size_t>(j * nx + i)]) {
        if (std::find(cand, cand + n_cand, k) != cand + n_cand) continue;
        if (n_cand == 16) {
          overflow = true;
          break;
        }
        cand[n_cand++] = k;
      }
  // A footprint spanning more patches (board far away) visits all of them.
  const int total = overflow ? static_cast<int>(board->patches.size()) : n_cand;

  // The perspective weights (FootprintWeight) are only needed where a black module cuts the
  // footprint: most pixels lie inside one module and return before.
  std::optional<FootprintWeight> weight;
  double area = -1.0;
  double weighted_area = 0.0;
  double black = 0.0;
  for (int c = 0; c < total; ++c) {
    const PatternPatch& p = board->patches[static_cast<size_t>(overflow ? c : cand[c])];
    const double m = p.module;
    int i0 = static_cast<int>(std::floor((bx0 - p.x0) / m));
    int i1 = static_cast<int>(std::floor((bx1 - p.x0) / m));
    int j0 = static_cast<int>(std::floor((by0 - p.y0) / m));
    int j1 = static_cast<int>(std::floor((by1 - p.y0) / m));
    if (i1 < 0 || j1 < 0 || i0 >= p.nx || j0 >= p.ny) continue;
    i0 = std::max(i0, 0);
    j0 = std::max(j0, 0);
    i1 = std::min(i1, p.nx - 1);
    j1 = std::min(j1, p.ny - 1);
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        if (!p.black[static_cast<size_t>(j * p.nx + i)]) continue;
        const double rx0 = p.x0 + i * m, ry0 = p.y0 + j * m;
        const double rx1 = rx0 + m, ry1 = ry0 + m;
        if (bx0 >= rx0 && bx1 <= rx1 && by0 >= ry0 && by1 <= ry1) return 1.0;  // all black
        if (area < 0) {
          weight.emplace(q);
          Eigen::Vector2d qc;
          area = polygon_moments(q.data(), 4, &qc);
          weighted_area = weight->weighted ? area * (*weight)(qc) : area;
        }
        Eigen::Vector2d pc;
        const double a = clipped_area(q, rx0, ry0, rx1, ry1, &pc);
        black += weight->weighted ? a * (*weight)(pc) : a;
      }
    }
  }
  if (area <= 0 || !(weighted_area != 0.0)) return 0.0;
  return std::clamp(black / weighted_area, 0.0, 1.0);
}

}  // namespace robocal::vision::detail
