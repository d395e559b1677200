// Fault injection of the simulated controller: fault plans (rates per kind, scripts), the draw
// for each received command, and faults voided by a rejected line.
#include "robocal/core/input_error.hpp"
#include "robocal/core/text_lines.hpp"
#include "sim_internal.hpp"

#include <fmt/core.h>

#include <array>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace robocal::robotio {
namespace {

constexpr std::array<const char*, kFaultKindCount> kFaultNames = {
    "drop", "busy",    "error",   "stall", "corrupt", "lost_ok", "resend",
    "slow", "garbage", "partial", "pstop", "missing", "shutdown"};

}  // namespace

const char* to_string(FaultKind kind) {
  return kFaultNames[static_cast<std::size_t>(kind)];
}

std::optional<FaultKind> fault_kind_from_string(const std::string& name) {
  for (std::size_t i = 0; i < kFaultNames.size(); ++i)
    if (name == kFaultNames[i]) return static_cast<FaultKind>(i);
  return std::nullopt;
}

FaultPlan parse_fault_spec(const std::string& spec) {
  FaultPlan plan;
  std::stringstream in(spec);
  std::string item;
  while (std::getline(in, item, ',')) {
    if (item.empty()) continue;
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos)
      throw std::invalid_argument("fault '" + item + "': expected KIND=RATE");
    const std::string kind = item.substr(0, eq);
    double rate = 0.0;
    try {
      rate = std::stod(item.substr(eq + 1));
    } catch (const std::exception&) {
      throw std::invalid_argument("fault '" + item + "': rate is not a number");
    }
    if (rate < 0.0 || rate > 1.0)
      throw std::invalid_argument("fault '" + item + "': rate must be within [0, 1]");
    if (kind == "all") {
      plan.rate.fill(rate);
      continue;
    }
    const auto k = fault_kind_from_string(kind);
    if (!k)
      throw std::invalid_argument("fault '" + kind +
                                  "': unknown kind (drop, busy, error, stall, corrupt, lost_ok, "
                                  "resend, slow, garbage, partial, pstop, missing, shutdown, all)");
    plan.rate[static_cast<std::size_t>(*k)] = rate;
  }
  return plan;
}

void load_fault_script(const std::string& path, FaultPlan& plan) {
  std::vector<core::ContentLine> lines;
  try {
    lines = core::read_content_lines(path);
  } catch (const core::InputError& e) {
    throw std::invalid_argument(e.what());
  }
  for (const core::ContentLine& line : lines) {
    std::stringstream ss(line.text);
    long index = 0;
    std::string kind;
    if (!(ss >> index) || !(ss >> kind) || index < 1)
      throw std::invalid_argument(
          fmt::format("{}:{}: expected '<command index> <kind>'", path, line.number));
    const auto k = fault_kind_from_string(kind);
    if (!k)
      throw std::invalid_argument(
          fmt::format("{}:{}: unknown fault kind '{}'", path, line.number, kind));
    plan.script[index] = *k;
  }
}

std::optional<FaultKind> SimController::Impl::draw_fault() {
  ++commands_received;
  const auto scripted = options.faults.script.find(commands_received);
  std::optional<FaultKind> f;
  if (scripted != options.faults.script.end()) {
    f = scripted->second;
  } else {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    // The line protocols draw only their kinds, so their fault sequences stay as they were.
    const std::size_t kinds = options.protocol == SimProtocol::kUr ? std::size_t{kUrFaultKindCount}
                              : options.protocol == SimProtocol::kMoonraker
                                  ? kFaultNames.size()
                                  : std::size_t{kLineFaultKindCount};
    for (std::size_t k = 0; k < kinds && !f; ++k) {
      const double r = u(fault_rng);  // always drawn: the sequence does not depend on hits
      if (r < options.faults.rate[k]) f = static_cast<FaultKind>(k);
    }
  }
  return f;
}

std::optional<FaultKind> SimController::Impl::roll_fault(const std::string& cmd) {
  const std::optional<FaultKind> f = draw_fault();
  if (!f) return f;
  const bool is_move = cmd.rfind("G1", 0) == 0 || cmd.rfind("G0", 0) == 0;
  // Faults that only make sense for some commands fall back to none elsewhere.
  if (*f == FaultKind::kStall && !is_move) return std::nullopt;
  if (*f == FaultKind::kPartial && cmd.rfind("M114", 0) != 0) return std::nullopt;
  // A stop must always get through: never fault the commands that stop the robot.
  if (cmd.rfind("M410", 0) == 0 || cmd.rfind("M112", 0) == 0 || cmd.rfind("M110", 0) == 0)
    return std::nullopt;
  return f;
}

// The open protocol has no checksums and no partial reports: those kinds draw nothing there. The
// handshake and the stop always get through.
std::optional<FaultKind> SimController::Impl::open_roll_fault(const std::string& cmd) {
  const std::optional<FaultKind> f = draw_fault();
  if (!f || cmd == "hello" || cmd == "stop") return std::nullopt;
  if (*f == FaultKind::kCorrupt || *f == FaultKind::kResend || *f == FaultKind::kPartial)
    return std::nullopt;
  if (*f == FaultKind::kStall && cmd != "move") return std::nullopt;
  return f;
}

// A UR's faults act on the motion (movej): a dropped connection, a refused script, a stall, late
// or missing RTDE packages, a protective stop. stopj and the dashboard always get through.
std::optional<FaultKind> SimController::Impl::ur_roll_fault(const std::string& cmd) {
  if (cmd != "movej") return std::nullopt;
  const std::optional<FaultKind> f = draw_fault();
  if (!f) return f;
  switch (*f) {
    case FaultKind::kDrop:
    case FaultKind::kError:
    case FaultKind::kStall:
    case FaultKind::kSlow:
    case FaultKind::kProtectiveStop:
    case FaultKind::kMissing:
      return f;
    default:
      return std::nullopt;
  }
}

// A fault drawn for a line the firmware then rejects (a duplicate line number after a lost ok)
// never takes effect: it is logged as void and not counted.
void SimController::Impl::void_fault(Channel& c, std::optional<FaultKind> fault) {
  if (!fault || *fault == FaultKind::kBusy || *fault == FaultKind::kGarbage ||
      *fault == FaultKind::kSlow)
    return;  // these happened before the line was judged
  --counters.faults[static_cast<std::size_t>(*fault)];
  write_log({{"ev", "fault_void"}, {"kind", to_string(*fault)}, {"ch", c.name}});
}
}  // namespace robocal::robotio
