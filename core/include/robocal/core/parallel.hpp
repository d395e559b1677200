#pragma once
// The project's one worker pool: runs fn(i) for i in [0, n) on up to `threads` threads.
#include <functional>

namespace robocal::core {

// Items are handed out in order to whichever worker is free; fn must be safe to call
// concurrently for different i. When fn throws, the exception of the lowest item that threw is
// rethrown here after every worker has stopped (the remaining items still run): the same error
// for any number of threads and any timing.
void parallel_for(int n, int threads, const std::function<void(int)>& fn);

}  // namespace robocal::core
