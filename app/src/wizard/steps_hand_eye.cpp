// The wizard's hand-eye route (robot.goal: handeye): after collection, where the cameras and the
// board are relative to the robot, from the flange poses the controller reported with every pose
// (or the robot file's nominal model where it reported none), written as YAML with the ROS 2
// static transform commands (the stage `robocal handeye` runs).
#include "stages/hand_eye.hpp"
#include "wizard/step.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <filesystem>

namespace robocal::app::wizard {
namespace {

namespace fs = std::filesystem;

class HandEyeStep final : public Step {
 public:
  std::string key() const override { return "handeye"; }
  std::string title() const override { return "Locate the cameras and the board (hand-eye)"; }
  std::string what() const override {
    return "The board's corners in every recorded pose and the flange pose the controller "
           "reported there give where each camera is relative to the robot and where the board "
           "sits on the flange (a camera on the tool: the camera on the flange and the board "
           "in the robot's base). The robot's own model is trusted as it is.";
  }
  bool applies(const WizardState& state) const override { return hand_eye_only(state); }
  StepOutcome run(WizardContext& ctx) override {
    HandEyeRequest request;
    request.images = ctx.state.session();
    const std::string mount = ctx.ask.choose(
        "handeye.mount", "Where are the cameras: fixed in the cell, or on the robot's tool",
        {"fixed", "tool"}, ctx.state.get("handeye.mount", "fixed"));
    ctx.state.set("handeye.mount", mount);
    request.mount =
        mount == "tool" ? vision::HandEyeMount::kCameraOnTool : vision::HandEyeMount::kFixedCamera;
    request.out = ctx.state.folder / "export" / "handeye.yaml";
    fs::create_directories(request.out.parent_path());
    PipelineLog log;
    log.out = ctx.out;
    const std::vector<HandEyeOutcome> outcomes = run_hand_eye(request, log);
    bool all_ok = true;
    for (const HandEyeOutcome& o : outcomes) {
      if (outcomes.size() > 1) fmt::print(ctx.out, "camera {}:\n", o.camera);
      fmt::print(ctx.out, "{}", hand_eye_summary(o.result, o.file.string()));
      all_ok = all_ok && o.result.status == vision::HandEyeStatus::kOk;
      if (o.result.status == vision::HandEyeStatus::kOk)
        ctx.state.set("handeye." + o.camera + ".file", o.file.string());
    }
    const auto failed = std::find_if(outcomes.begin(), outcomes.end(), [](const auto& o) {
      return o.result.status != vision::HandEyeStatus::kOk;
    });
    say_check(ctx, all_ok,
              all_ok ? "every camera located (" + request.out.parent_path().string() + ")"
                     : fmt::format("camera {}: {}", failed->camera, failed->result.reason),
              "record more poses turning the flange about at least two axes (a larger plan), "
              "check that the board is rigidly fixed, and run the wizard again");
    if (!all_ok) return StepOutcome::stopped("the hand-eye calibration was not accepted");
    return StepOutcome::done();
  }
};

}  // namespace

std::unique_ptr<Step> hand_eye_step() {
  return std::make_unique<HandEyeStep>();
}

}  // namespace robocal::app::wizard
