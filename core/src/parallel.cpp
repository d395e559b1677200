#include "robocal/core/parallel.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace robocal::core {

void parallel_for(int n, int threads, const std::function<void(int)>& fn) {
  std::atomic<int> next{0};
  std::vector<std::thread> pool;
  std::exception_ptr error;
  int error_item = n;  // the lowest item that threw: the same error whatever the timing
  std::mutex error_mutex;
  for (int w = 0; w < std::max(1, std::min(threads, n)); ++w) {
    pool.emplace_back([&] {
      for (int i = next++; i < n; i = next++) {
        try {
          fn(i);
        } catch (...) {
          const std::lock_guard<std::mutex> lock(error_mutex);
          if (i < error_item) {
            error = std::current_exception();
            error_item = i;
          }
        }
      }
    });
  }
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace robocal::core
