// Observability selection on the Delta cell.
#include "robocal/calib/robot_file.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/plan.hpp"

#include <gtest/gtest.h>

#include <iostream>

namespace robocal::planner {
namespace {

const std::string kData = std::string(ROBOCAL_TESTDATA_DIR);

TEST(PlannerSmoke, DeltaCell) {
  const calib::Mechanism model = calib::load_robot_file(kData + "/robots/rotary_delta.yaml");
  const Cell cell = load_cell_file(kData + "/cells/delta_two_cameras.yaml");
  PlanOptions o;
  o.pool = 1000;
  o.selection.count = 40;
  o.progress = [](const std::string& s) { std::cerr << s << "\n"; };
  const PlanResult r = plan_measurements(model, model.nominal_parameters(), cell, o);
  std::cerr << r.message << "\n"
            << r.counts.summary() << "\n tour " << r.tour.length << " nn "
            << r.tour.nearest_neighbour_length << " t " << r.plan_seconds << "\n";
  for (const auto& w : r.warnings) std::cerr << w << "\n";
}

}  // namespace
}  // namespace robocal::planner
