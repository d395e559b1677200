#include "robocal/calib/frame_checks.hpp"

#include <cmath>
#include <cstdio>

namespace robocal::calib {

std::vector<std::string> gimbal_lock_warnings(const Mechanism& model, double margin_deg) {
  std::vector<std::string> out;
  for (const Body& body : model.bodies) {
    if (body.convention != "xyz_rpy") continue;
    // The three roll/pitch/yaw ops are the consecutive rotations carrying a parameter named
    // .roll/.pitch/.yaw; the middle one decides the lock.
    for (std::size_t k = 0; k + 2 < body.ops.size(); ++k) {
      const auto& a = body.ops[k];
      const auto& m = body.ops[k + 1];
      const auto& c = body.ops[k + 2];
      auto is_rot = [](const ElementaryOp& op) {
        return op.kind == OpKind::kRotX || op.kind == OpKind::kRotY || op.kind == OpKind::kRotZ;
      };
      if (!is_rot(a) || !is_rot(m) || !is_rot(c) || m.param < 0 || a.joint || m.joint || c.joint)
        continue;
      const std::string& name = model.parameters[static_cast<std::size_t>(m.param)].name;
      if (name.size() < 6 || name.compare(name.size() - 6, 6, ".pitch") != 0) continue;
      const double pitch = model.parameters[static_cast<std::size_t>(m.param)].value;
      const double off = std::abs(std::abs(std::remainder(pitch, M_PI)) - M_PI / 2.0);
      if (off * 180.0 / M_PI > margin_deg) continue;
      char text[512];
      std::snprintf(text, sizeof text,
                    "body '%s' (line %d): pitch %.4g deg is %.2g deg from gimbal lock; its roll "
                    "and yaw turn about nearly the same axis, so identification cannot separate "
                    "them. Give the frame as `orientation: {quaternion: [w, x, y, z]}` (roll/"
                    "pitch/yaw then act as small corrections) or change rotation_order.",
                    body.name.c_str(), body.line, pitch * 180.0 / M_PI, off * 180.0 / M_PI);
      out.emplace_back(text);
      break;
    }
  }
  return out;
}

}  // namespace robocal::calib
