#pragma once
// Random vectors drawn one component at a time, in a fixed order.
//
// Each draw is a statement of its own: the evaluation order of function arguments is unspecified,
// so `Eigen::Vector3d(d(rng), d(rng), d(rng))` may give another vector from the same seed with
// another compiler. The order kept, last component first, is the one the stored figures were
// drawn in.
#include <Eigen/Core>

namespace robocal::core {

// Three draws of `distribution` from `engine`: z, then y, then x.
template <class Distribution, class Engine>
Eigen::Vector3d draw_vector3(Distribution& distribution, Engine& engine) {
  const double z = distribution(engine);
  const double y = distribution(engine);
  const double x = distribution(engine);
  return Eigen::Vector3d(x, y, z);
}

// Two draws of `distribution` from `engine`: y, then x.
template <class Distribution, class Engine>
Eigen::Vector2d draw_vector2(Distribution& distribution, Engine& engine) {
  const double y = distribution(engine);
  const double x = distribution(engine);
  return Eigen::Vector2d(x, y);
}

}  // namespace robocal::core
