#pragma once
// How a stage talks while it runs: lines and progress bars on the log's stream (none when the
// log is silent, e.g. sessions processed in parallel) and sub-stage timing on its clock.
#include "cli/progress.hpp"
#include "stages/measure_steps.hpp"
#include "stages/stages.hpp"

#include <fmt/core.h>

#include <string>
#include <utility>

namespace robocal::app {

template <typename... Args>
void say(const PipelineLog& log, fmt::format_string<Args...> format, Args&&... args) {
  if (log.out) fmt::print(log.out, format, std::forward<Args>(args)...);
}

inline void stage(const PipelineLog& log, const std::string& name) {
  if (log.clock) log.clock->start(name);
}

inline StepLog step_log(const PipelineLog& log) {
  return {log.out, log.threads};
}

}  // namespace robocal::app
