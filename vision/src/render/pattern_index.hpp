#pragma once
// How much of a pixel's footprint on a board is black (internal to the renderer).
#include "robocal/vision/target.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

namespace robocal::vision::detail {

// Uniform grid over a board's paper listing the patches that overlap each cell, so a footprint
// only visits the one or two patches near it.
struct PatternIndex {
  const TargetBoard* board = nullptr;
  double x0 = 0, y0 = 0, cell = 1;
  int nx = 1, ny = 1;
  std::vector<std::vector<int>> cells;

  explicit PatternIndex(const TargetBoard& b) : board(&b) {
    x0 = b.extent_min.x();
    y0 = b.extent_min.y();
    const Eigen::Vector2d size = b.extent_max - b.extent_min;
    cell = std::max(size.x(), size.y());
    for (const PatternPatch& p : b.patches) cell = std::min(cell, std::max(p.nx, p.ny) * p.module);
    cell = std::max({cell, size.x() / 512, size.y() / 512, 1e-9});
    nx = std::max(1, static_cast<int>(std::ceil(size.x() / cell)));
    ny = std::max(1, static_cast<int>(std::ceil(size.y() / cell)));
    cells.resize(static_cast<size_t>(nx * ny));
    for (int k = 0; k < static_cast<int>(b.patches.size()); ++k) {
      const PatternPatch& p = b.patches[static_cast<size_t>(k)];
      const int i0 = cell_x(p.x0), i1 = cell_x(p.x0 + p.nx * p.module);
      const int j0 = cell_y(p.y0), j1 = cell_y(p.y0 + p.ny * p.module);
      for (int j = j0; j <= j1; ++j)
        for (int i = i0; i <= i1; ++i) cells[static_cast<size_t>(j * nx + i)].push_back(k);
    }
    for (const PatternPatch& p : b.patches) inverse_module.push_back(1.0 / p.module);
    for (std::size_t a = 0; a < b.patches.size(); ++a)
      for (std::size_t c = a + 1; c < b.patches.size(); ++c) {
        const PatternPatch& p = b.patches[a];
        const PatternPatch& r = b.patches[c];
        const bool overlap_x =
            std::max(p.x0, r.x0) < std::min(p.x0 + p.nx * p.module, r.x0 + r.nx * r.module);
        const bool overlap_y =
            std::max(p.y0, r.y0) < std::min(p.y0 + p.ny * p.module, r.y0 + r.ny * r.module);
        if (overlap_x && overlap_y) patches_apart = false;
      }
  }
  int cell_x(double x) const {
    return std::clamp(static_cast<int>(std::floor((x - x0) / cell)), 0, nx - 1);
  }
  int cell_y(double y) const {
    return std::clamp(static_cast<int>(std::floor((y - y0) / cell)), 0, ny - 1);
  }

  bool black_at(double x, double y) const {
    for (int k : cells[static_cast<size_t>(cell_y(y) * nx + cell_x(x))]) {
      const PatternPatch& p = board->patches[static_cast<size_t>(k)];
      const double u = (x - p.x0) / p.module, v = (y - p.y0) / p.module;
      if (u < 0 || v < 0 || u >= p.nx || v >= p.ny) continue;
      if (p.black[static_cast<size_t>(static_cast<int>(v) * p.nx + static_cast<int>(u))])
        return true;
    }
    return false;
  }

  // Fraction of the convex quad q (board coordinates) covered by black modules.
  double black_fraction(const std::array<Eigen::Vector2d, 4>& q) const;

  // The module a board point lies in, as black_at finds it: -1 where none (paper). A footprint
  // whose four corners share a module lies inside it (both are convex).
  std::int64_t module_at(double x, double y) const {
    for (int k : cells[static_cast<size_t>(cell_y(y) * nx + cell_x(x))]) {
      const PatternPatch& p = board->patches[static_cast<size_t>(k)];
      // A multiplication where black_at divides: a point on a module's side may land in its
      // neighbour, and inside_module then leaves it to black_fraction.
      const double per_module = inverse_module[static_cast<size_t>(k)];
      const double u = (x - p.x0) * per_module, v = (y - p.y0) * per_module;
      if (u < 0 || v < 0 || u >= p.nx || v >= p.ny) continue;
      return (static_cast<std::int64_t>(k) << 32) |
             static_cast<std::int64_t>(static_cast<int>(v) * p.nx + static_cast<int>(u));
    }
    return -1;
  }

  // black_fraction(q) for a footprint whose corners all lie in `module` (module_at), without its
  // search: 1 or 0 where q keeps a margin from the module's sides (so black_fraction's own
  // rounding finds that module alone, and no other patch's), nullopt otherwise. Most pixels of
  // a near board are such footprints.
  std::optional<double> inside_module(const std::array<Eigen::Vector2d, 4>& q,
                                      std::int64_t module) const {
    const PatternPatch& p = board->patches[static_cast<size_t>(module >> 32)];
    const auto index = static_cast<int>(module & 0xffffffff);
    const double m = p.module;
    const int column = index % p.nx, row = index / p.nx;  // as black_fraction's i, j
    const double rx0 = p.x0 + column * m, ry0 = p.y0 + row * m;
    const double rx1 = rx0 + m, ry1 = ry0 + m;
    const double margin = 1e-9 * m;
    for (const Eigen::Vector2d& c : q)
      if (!(c.x() >= rx0 + margin && c.x() <= rx1 - margin && c.y() >= ry0 + margin &&
            c.y() <= ry1 - margin))
        return std::nullopt;
    if (p.black[static_cast<size_t>(index)]) return 1.0;
    if (patches_apart) return 0.0;
    return std::nullopt;  // another patch may overlap this white module
  }

  // No two patches overlap (true of every board target.hpp builds): a white module is white.
  bool patches_apart = true;
  std::vector<double> inverse_module;  // 1 / module side, per patch
};

}  // namespace robocal::vision::detail
