#pragma once
// The process's memory, as the operating system counts it: what a long survey's report shows scan
// by scan (docs/scaling.md). Linux reads /proc/self/statm and getrusage; elsewhere both are 0.
//
// Thread-safety: reentrant.
#include <cstddef>

namespace minemap {

/// Resident set size now, bytes (0 where the system does not say).
std::size_t resident_bytes();
/// The largest resident set size so far, bytes (0 where the system does not say).
std::size_t peak_resident_bytes();

}  // namespace minemap
