// `robocal handeye`: where the camera and the board are relative to the robot, from images and
// the flange poses its controller reported (no kinematic model).
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "stages/hand_eye.hpp"

#include "robocal/vision/hand_eye_io.hpp"

#include <fmt/core.h>

#include <memory>

namespace robocal::app {

CommandSpec handeye_command() {
  return {"handeye",
          "Locate the camera and the board relative to the robot from the flange poses its "
          "controller reports (hand-eye calibration)",
          [](CLI::App& cmd) -> CommandAction {
            auto request = std::make_shared<HandEyeRequest>();
            auto images = std::make_shared<std::string>();
            auto poses = std::make_shared<std::string>();
            auto target = std::make_shared<std::string>();
            auto camera = std::make_shared<std::string>();
            auto out = std::make_shared<std::string>("handeye.yaml");
            auto mount = std::make_shared<std::string>("fixed");
            auto threads = std::make_shared<int>(2);
            cmd.footer(
                "For a robot whose own accuracy is trusted (a UR5, an industrial arm with its own "
                "calibration): no kinematic model, only the base -> flange pose the controller "
                "reported for each image. A fixed camera gives the camera in the base frame and "
                "the board in the flange frame; a camera on the tool (--mount tool) the camera "
                "in the flange frame and the board in the base frame.\n\n"
                "IMAGES is a folder of images with --poses and --target, or a session folder "
                "recorded by `robocal collect` or the wizard: then each camera is solved with the "
                "intrinsics `robocal measure` calibrated (or else those collect recorded), and the "
                "flange is the pose the controller reported with each pose (pose.yaml "
                "flange_pose: a UR, an industrial arm, an open link adapter with flange_pose) when "
                "every usable pose has one, otherwise the session's measured frame at the robot "
                "file's nominal model for the recorded readings; the command says which (one "
                "result file per camera, OUT_<camera>.yaml, when there are several).\n\n"
                "POSES is a folder with one YAML file per image (3.png -> 3.yaml: x y z in "
                "metres, qx qy qz qw) or a YAML list of {image, pose} entries. Without --camera "
                "the intrinsics are calibrated from the same images first. A closed form starts a "
                "bundle adjustment on the corner pixels of every view (with --estimate-intrinsics "
                "the intrinsics too); views that disagree with the rest are named and left out. "
                "Flange positions in millimetres, quaternions written w first and the wrong "
                "mounting are recognised and refused with what to change. Writes OUT only when "
                "the estimate is accepted: both transforms with their covariance, every view's "
                "reprojection and the ROS 2 static transform commands.");
            cmd.add_option("images", *images, "Folder of images of the board, or a session folder")
                ->required();
            cmd.add_option("--poses", *poses, "Flange poses: folder of IMAGE.yaml or a list file");
            cmd.add_option("--target", *target, "Board file (robocal target)");
            cmd.add_option("--camera", *camera, "Camera file (robocal intrinsics)");
            cmd.add_flag("--estimate-intrinsics", request->estimate_intrinsics,
                         "Refine the intrinsics together with the two transforms");
            cmd.add_option("--mount", *mount, "Where the camera is: fixed or tool")
                ->check(CLI::IsMember({"fixed", "tool"}))
                ->capture_default_str();
            cmd.add_option("-o,--out", *out, "Result file (YAML)")->capture_default_str();
            cmd.add_option("--threads", *threads, "Detection workers")
                ->check(CLI::Range(1, 64))
                ->capture_default_str();
            return [request, images, poses, target, camera, out, mount, threads]() {
              request->images = *images;
              request->poses = *poses;
              request->target = *target;
              if (!camera->empty()) request->camera = *camera;
              request->out = *out;
              request->mount = *mount == "tool" ? vision::HandEyeMount::kCameraOnTool
                                                : vision::HandEyeMount::kFixedCamera;
              PipelineLog log;
              log.threads = *threads;
              const auto outcomes = run_hand_eye(*request, log);
              bool all_ok = true;
              for (const auto& o : outcomes) {
                if (outcomes.size() > 1) fmt::print("camera {}:\n", o.camera);
                fmt::print("{}", hand_eye_summary(o.result, o.file.string()));
                all_ok = all_ok && o.result.status == vision::HandEyeStatus::kOk;
              }
              if (all_ok) return 0;
              for (const auto& o : outcomes)
                if (o.result.status != vision::HandEyeStatus::kOk)
                  fmt::print(
                      stderr, "error: hand-eye calibration of {} {}: {}\n", o.camera,
                      o.result.status == vision::HandEyeStatus::kRefused ? "refused" : "failed",
                      o.result.reason);
              fmt::print(stderr, "nothing written\n");
              return 1;
            };
          }};
}

}  // namespace robocal::app
