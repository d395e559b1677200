#include "stages/cell_truth.hpp"

#include <fmt/core.h>

namespace robocal::app {

TruthFile cell_truth(const SimulatedCell& cell, const std::string& source) {
  TruthFile truth;
  truth.elastic_sag = cell.elastic_sag;
  truth.nominal = cell.nominal;
  truth.truth = cell.truth;
  for (std::size_t c = 0; c < cell.cameras.size(); ++c)
    truth.cameras.push_back(
        {fmt::format("cam{}", c), cell.cameras[c].model, cell.cameras[c].camera_T_world});
  truth.perturbation.length_sigma_m = cell.options.length_sigma;
  truth.perturbation.angle_sigma_rad = cell.options.angle_sigma;
  truth.perturbation.source = source;
  return truth;
}

}  // namespace robocal::app
