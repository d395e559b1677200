#include "cli/command_registry.hpp"

#include <glog/logging.h>
#include <malloc.h>

int main(int argc, char** argv) {
  // Rendering and detection allocate and free image buffers by the thousand, several of 7.7 MB
  // (a 1600x1200 frame's light in floats) per rendered frame, on several threads. By default
  // glibc hands such blocks back to the kernel when they are freed (mmap'd blocks, a heap's free
  // top), so the next frame's buffers were page-faulted and zeroed by the kernel again: a quarter
  // of the rendering time. Kept in the heap, they are reused as they are.
  mallopt(M_MMAP_THRESHOLD, 32 << 20);   // glibc's largest: blocks below it come from the heap
  mallopt(M_TRIM_THRESHOLD, 128 << 20);  // a heap keeps up to this much free memory at its top
  // Ceres logs through glog; its per-iteration warnings ("step failed to evaluate") are solver
  // internals, not something an operator can act on. Our commands report solver outcomes.
  FLAGS_minloglevel = google::GLOG_ERROR;
  FLAGS_logtostderr = true;
  google::InitGoogleLogging(argv[0]);
  return robocal::app::run_cli(argc, argv);
}
