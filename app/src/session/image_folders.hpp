#pragma once
// Image folders of per-view / per-pose sub-folders (vision/README_rig.md, app/SESSION.md): per
// camera, the image files of each frame ("<camera>.<ext>" or "<camera>_<k>.<ext>", k = 0, 1, ...
// in order).
#include <filesystem>
#include <string>
#include <vector>

namespace robocal::app {

// One sub-folder (a view or a robot pose).
struct ImageSet {
  std::string name;                                                  // sub-folder name
  std::vector<std::vector<std::filesystem::path>> frames_of_camera;  // [camera][frame]
};

// Sub-folders sorted by name. Throws InputError if the folder is missing or has no sub-folders.
std::vector<ImageSet> scan_image_folder(const std::filesystem::path& folder,
                                        const std::vector<std::string>& camera_names);

}  // namespace robocal::app
