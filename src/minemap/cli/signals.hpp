#pragma once
// Internal to the command line. Ctrl-C (SIGINT) and SIGTERM while `map` or `watch` runs: counted
// by a handler, read through the questions below, never as a raw count.
//  * map: the first stops the run at the next scan boundary (the partial map is written, exit 130).
//  * watch: the first finishes the map (as map does); the second stops at the next boundary.
//
// Thread-safety: the count is a sig_atomic_t written only by the handler; one InterruptHandlers at
// a time (run() installs it; not reentrant).
#include <signal.h>

namespace minemap::cli::signals {

/// Installs the handlers while alive (resetting the count) and restores the previous ones (the
/// Python interpreter's, when the package runs the command line).
class InterruptHandlers {
 public:
  InterruptHandlers();
  ~InterruptHandlers();
  InterruptHandlers(const InterruptHandlers&) = delete;
  InterruptHandlers& operator=(const InterruptHandlers&) = delete;

 private:
  struct sigaction previous_int_ {};
  struct sigaction previous_term_ {};
};

/// Blocks SIGINT and SIGTERM while alive: outputs are written completely or not at all, and a
/// signal that arrived meanwhile is delivered (and honoured) once the writing is done.
class SignalsBlocked {
 public:
  SignalsBlocked();
  ~SignalsBlocked();
  SignalsBlocked(const SignalsBlocked&) = delete;
  SignalsBlocked& operator=(const SignalsBlocked&) = delete;

 private:
  sigset_t previous_;
};

/// At least one interrupt arrived: map stops, watch finishes.
bool interrupted();
/// A second interrupt arrived: watch stops at once.
bool interrupted_twice();

/// Thrown when an interrupt arrived while the outputs were written (they are complete).
struct Interrupted {};

}  // namespace minemap::cli::signals
