#pragma once
// The hidden truth of a simulated cell as validate reads it (session/results_files.hpp's
// TruthFile): the one record `simulate`, the live demo and `sim-cell` write.
#include "session/results_files.hpp"
#include "simcell/simulated_cell.hpp"

#include <string>

namespace robocal::app {

// The true robot, the true cameras (named cam0, cam1, … as every simulated session names them)
// and the tolerances the truth was drawn with; no poses (the caller adds the poses it recorded).
// `source`: which simulator holds the truth.
TruthFile cell_truth(const SimulatedCell& cell, const std::string& source);

}  // namespace robocal::app
