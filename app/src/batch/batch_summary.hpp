#pragma once
// The JSON summary of `robocal batch` and its table, in one place: an unsharded run, a shard
// (with its "shard" section, batch_shard.hpp) and a merge of shards all write this document.
#include <nlohmann/json.hpp>

#include <cstdio>
#include <vector>

namespace robocal::app {

// {"sessions": rows, "ok": sessions with status "ok", "failed": the others}.
nlohmann::json batch_summary(const std::vector<nlohmann::json>& rows);

// The table a person reads: poses used, identify, nominal and calibrated error, seconds; then
// "K of N sessions ok".
void print_batch_table(std::FILE* out, const std::vector<nlohmann::json>& rows);

// Batch's exit code: 0 when every session is ok, 1 when any failed.
int batch_exit_code(const nlohmann::json& summary);

}  // namespace robocal::app
