#pragma once
// Target files (YAML) and printable SVG. Examples (lengths in metres):
//
//   type: apriltag_grid      # AprilTag 3 grid with a white quiet zone around every tag
//   family: tag36h11         # default; also tag25h9, tag16h5
//   cols: 6                  # tags across
//   rows: 4                  # tags down
//   tag_size: 0.04           # side of the black square (what AprilTag's corners span)
//   tag_spacing: 0.012       # gap between black squares; default 0.3 * tag_size, >= 2 modules
//   first_id: 0              # ids first_id, first_id+1, ... in id_order
//   id_order: row_major      # or column_major
//   # ids: [...]             # or an explicit row-major list of cols*rows ids
//   margin: 0.012            # white border around the grid; default tag_spacing
//
//   type: chessboard         # cols x rows squares, top-left black; margin default square_size
//   cols: 9
//   rows: 7
//   square_size: 0.03
//
//   type: charuco            # OpenCV 4.6 layout (see target.hpp); margin default square/2
//   cols: 7
//   rows: 5
//   square_size: 0.04
//   marker_size: 0.02
//   dictionary: DICT_6X6_250
//
// Optional for all: name (text).
#include "robocal/vision/errors.hpp"
#include "robocal/vision/target.hpp"

#include <filesystem>
#include <string>

namespace robocal::vision {

// Throw FileFormatError("<file>:<line>: <problem>").
TargetBoard load_target_file(const std::filesystem::path& path);
TargetBoard parse_target_yaml(const std::string& text, const std::string& source);
// The YAML text of a (resolved) spec; parse_target_yaml(target_to_yaml(s)) rebuilds the board.
std::string target_to_yaml(const TargetSpec& spec);

// True-scale SVG (width/height in millimetres, 1 user unit = 1 mm) of the whole paper
// (pattern + margin): print at 100 % / "actual size" and measure the scale bar-free pattern:
// the SVG's comment states the expected pattern size.
std::string target_to_svg(const TargetBoard& board);
void save_target_svg(const TargetBoard& board, const std::filesystem::path& path);
// Single-page PDF of the same drawing, page size = paper size (points, 1 pt = 1/72 inch).
std::string target_to_pdf(const TargetBoard& board);
void save_target_pdf(const TargetBoard& board, const std::filesystem::path& path);

}  // namespace robocal::vision
