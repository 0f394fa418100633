#include "minemap/cli/signals.hpp"

#include <pthread.h>

#include <csignal>

namespace minemap::cli::signals {
namespace {

/// Interrupts received since the handlers were installed, at most 2.
volatile std::sig_atomic_t g_interrupts = 0;
extern "C" void on_interrupt(int) {
  if (g_interrupts < 2) g_interrupts = g_interrupts + 1;
}

}  // namespace

InterruptHandlers::InterruptHandlers() {
  g_interrupts = 0;
  struct sigaction action {};
  action.sa_handler = on_interrupt;
  action.sa_flags = SA_RESTART;  // as std::signal: reads and writes in flight are not cut short
  sigemptyset(&action.sa_mask);
  ::sigaction(SIGINT, &action, &previous_int_);
  ::sigaction(SIGTERM, &action, &previous_term_);
}

InterruptHandlers::~InterruptHandlers() {
  ::sigaction(SIGINT, &previous_int_, nullptr);
  ::sigaction(SIGTERM, &previous_term_, nullptr);
}

SignalsBlocked::SignalsBlocked() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  ::pthread_sigmask(SIG_BLOCK, &set, &previous_);
}

SignalsBlocked::~SignalsBlocked() { ::pthread_sigmask(SIG_SETMASK, &previous_, nullptr); }

bool interrupted() { return g_interrupts >= 1; }
bool interrupted_twice() { return g_interrupts >= 2; }

}  // namespace minemap::cli::signals
