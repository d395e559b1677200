#include "session/image_folders.hpp"

#include "cli/cli_common.hpp"

#include "robocal/vision/intrinsics_pipeline.hpp"

#include <algorithm>
#include <cctype>
#include <utility>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

// Frame number of `file` for `camera` ("<camera>.<ext>" = 0, "<camera>_<k>.<ext>" = k), or -1.
int frame_number(const fs::path& file, const std::string& camera) {
  if (!vision::is_image_file(file)) return -1;
  const std::string stem = file.stem().string();
  if (stem == camera) return 0;
  if (stem.size() <= camera.size() + 1 || stem.compare(0, camera.size(), camera) != 0 ||
      stem[camera.size()] != '_')
    return -1;
  const std::string digits = stem.substr(camera.size() + 1);
  if (digits.size() > 6 ||
      !std::all_of(digits.begin(), digits.end(), [](unsigned char ch) { return std::isdigit(ch); }))
    return -1;
  return std::stoi(digits);
}

}  // namespace

std::vector<ImageSet> scan_image_folder(const fs::path& folder,
                                        const std::vector<std::string>& camera_names) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder.string() + ": not a folder");
  std::vector<fs::path> subs;
  for (const auto& e : fs::directory_iterator(folder, ec))
    if (e.is_directory()) subs.push_back(e.path());
  std::sort(subs.begin(), subs.end());
  if (subs.empty())
    throw InputError(folder.string() + ": no sub-folders (one per view / robot pose expected)");
  std::vector<ImageSet> out;
  for (const auto& sub : subs) {
    ImageSet set;
    set.name = sub.filename().string();
    set.frames_of_camera.resize(camera_names.size());
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(sub, ec))
      if (e.is_regular_file()) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (size_t c = 0; c < camera_names.size(); ++c) {
      std::vector<std::pair<int, fs::path>> frames;
      for (const auto& file : files) {
        const auto frame_no = frame_number(file, camera_names[c]);
        if (frame_no >= 0) frames.emplace_back(frame_no, file);
      }
      std::sort(frames.begin(), frames.end());
      for (const auto& [k, p] : frames) set.frames_of_camera[c].push_back(p);
    }
    out.push_back(set);
  }
  return out;
}

}  // namespace robocal::app
