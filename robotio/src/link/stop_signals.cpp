#include "robocal/robotio/stop_signals.hpp"

#include <atomic>
#include <stdexcept>

namespace robocal::robotio {
namespace {

std::atomic<SafetyGuard*> g_guard{nullptr};
std::atomic<bool> g_paused{false};
std::atomic<int> g_stop_signal{0};

extern "C" void on_stop_signal(int sig) {
  SafetyGuard* guard = g_guard.load();
  if (sig == SIGINT && (guard == nullptr || guard->stop_requested())) {
    std::signal(SIGINT, SIG_DFL);  // a second Ctrl-C: the operator wants out now
    std::raise(SIGINT);
    return;
  }
  g_stop_signal = sig;
  if (guard != nullptr) guard->request_stop_from_signal();
}

extern "C" void on_pause_signal(int /*sig*/) {
  g_paused = !g_paused.load();
}

void install(int sig, void (*handler)(int), struct sigaction* old) {
  struct sigaction sa {};
  sa.sa_handler = handler;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: blocking reads return EINTR and the link notices the stop
  sigaction(sig, &sa, old);
}

}  // namespace

StopSignals::StopSignals(SafetyGuard& guard) {
  SafetyGuard* expected = nullptr;
  if (!g_guard.compare_exchange_strong(expected, &guard))
    throw std::logic_error("StopSignals: another instance already holds the signals");
  g_stop_signal = 0;
  g_paused = false;
  install(SIGINT, on_stop_signal, &old_int_);
  install(SIGTERM, on_stop_signal, &old_term_);
  install(SIGUSR1, on_pause_signal, &old_usr1_);
}

StopSignals::~StopSignals() {
  sigaction(SIGINT, &old_int_, nullptr);
  sigaction(SIGTERM, &old_term_, nullptr);
  sigaction(SIGUSR1, &old_usr1_, nullptr);
  g_guard = nullptr;
}

int StopSignals::stop_signal() {
  return g_stop_signal.load();
}
bool StopSignals::paused() {
  return g_paused.load();
}
void StopSignals::toggle_pause() {
  g_paused = !g_paused.load();
}

}  // namespace robocal::robotio
