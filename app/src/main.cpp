#include "cli/command_registry.hpp"

#include <glog/logging.h>

int main(int argc, char** argv) {
  // Ceres logs through glog; its per-iteration warnings ("step failed to evaluate") are solver
  // internals, not something an operator can act on. Our commands report solver outcomes.
  FLAGS_minloglevel = google::GLOG_ERROR;
  FLAGS_logtostderr = true;
  google::InitGoogleLogging(argv[0]);
  return robocal::app::run_cli(argc, argv);
}
