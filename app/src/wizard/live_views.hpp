#pragma once
// Calibration views taken live (the intrinsics step's 'live' answer): the operator holds the
// calibration board in front of one camera and presses Enter for each view. A frame in which the
// board is found is kept in the wizard's calibration folder (app/SESSION.md layout:
// calibration/intrinsics/<camera>/view_NNN.png); after each kept view the wizard shows how the
// image is covered and what to add, from a calibration of the views so far (its refusal or its
// advice, in plain words: "tilt the board more", "reach the corners"). 'done' ends the capture
// and the step calibrates from the folder as from any folder of views; 'quit' stops the wizard
// with every view kept, and a resumed wizard goes on numbering after them.
#include "wizard/step.hpp"

#include "robocal/robotio/camera_source.hpp"
#include "robocal/vision/intrinsic_calibration.hpp"
#include "robocal/vision/target.hpp"

#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace robocal::app::wizard {

// The coverage of the image by board corners, as a character grid ('.' none ... '#' many).
void print_coverage(std::FILE* out, const vision::CoverageMap& map);

// The source the cameras step was given for `camera` (NAME=SOURCE in cameras.list; empty if
// none) and the frame size it set (cameras.size WIDTHxHEIGHT; 0 x 0 for 'keep').
std::string camera_source(const WizardState& s, const std::string& camera);
std::pair<int, int> camera_frame_size(const WizardState& s);

// Opens `source` (live/sim_camera.hpp: aravis:, v4l2:, sim:) delivering frames of width x height,
// or of its whole sensor when width is 0 (a camera keeps the region its last user set).
std::unique_ptr<robotio::CameraSource> open_camera_at(const std::string& source,
                                                      const std::string& camera, int width,
                                                      int height);

// Takes views of `board` from the camera `camera` (opened from `source`, e.g. aravis:ID; frames
// of width x height when width > 0). Returns the folder of kept views after 'done', or nullopt
// after 'quit' or when there is no terminal (`why` says which and what to do).
std::optional<std::filesystem::path> take_live_views(WizardContext& ctx, const std::string& camera,
                                                     const std::string& source,
                                                     const vision::TargetBoard& board, int width,
                                                     int height, std::string& why);

// Rig views taken live (the identify step's 'live' answer): the board held where two or more
// cameras see it at once; each Enter takes a frame from every camera, kept as
// `into`/view_NNN/<camera>.png when at least two of them see the board. Returns `into` after
// 'done', or nullopt after 'quit' or without a terminal (`why` says which).
std::optional<std::filesystem::path> take_live_rig_views(
    WizardContext& ctx, const std::vector<std::pair<std::string, std::string>>& cameras,
    const vision::TargetBoard& board, int width, int height, const std::filesystem::path& into,
    std::string& why);

}  // namespace robocal::app::wizard
