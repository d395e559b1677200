#include "robocal/robotio/link_factory.hpp"

#include "robocal/robotio/klipper_link.hpp"
#include "robocal/robotio/manual_link.hpp"
#include "robocal/robotio/open_link.hpp"
#include "robocal/robotio/ur_link.hpp"

namespace robocal::robotio {

std::unique_ptr<RobotLink> make_robot_link(SafetyGuard& guard, const GcodeLinkOptions& options) {
  if (options.address == "manual") return std::make_unique<ManualLink>(guard, ManualLinkOptions{});
  if (is_open_link_address(options.address)) {
    OpenLinkOptions o;
    o.address = options.address;
    o.reply_timeout = options.reply_timeout;
    o.attempts = options.attempts;
    o.reconnect_attempts = options.reconnect_attempts;
    return std::make_unique<OpenLink>(guard, o);
  }
  if (is_ur_link_address(options.address)) {
    UrLinkOptions o;
    o.address = options.address;
    o.reply_timeout = options.reply_timeout;
    o.reconnect_attempts = options.reconnect_attempts;
    o.unlock_protective_stop = options.unlock_protective_stop;
    return std::make_unique<UrLink>(guard, o);
  }
  if (is_moonraker_address(options.address)) return std::make_unique<KlipperLink>(guard, options);
  return std::make_unique<GcodeLink>(guard, options);
}

std::optional<CarriageFrame> firmware_delta_frame(const RobotLink& link) {
  if (const auto* gcode = dynamic_cast<const GcodeLink*>(&link)) return gcode->native_frame();
  if (const auto* klipper = dynamic_cast<const KlipperLink*>(&link)) return klipper->native_frame();
  return std::nullopt;
}

}  // namespace robocal::robotio
