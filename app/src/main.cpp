#include "command_registry.hpp"

int main(int argc, char** argv) {
  return robocal::app::run_cli(argc, argv);
}
