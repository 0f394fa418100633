#pragma once
// Internal to src/minemap/io: little-endian loads and stores for the binary formats (PCD binary, PLY
// binary_little_endian, KITTI .bin). memcpy keeps unaligned access defined; the formats are
// little-endian and so is every machine minemap targets (checked at compile time).
#include <bit>
#include <cstdint>
#include <cstring>
#include <string>

namespace minemap::io::detail {

static_assert(std::endian::native == std::endian::little,
              "the binary readers assume a little-endian host (PCD binary is host order, PLY/KITTI are LE)");

template <class T>
T load_le(const char* bytes) {
  T value;
  std::memcpy(&value, bytes, sizeof(T));
  return value;
}

template <class T>
void append_le(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

}  // namespace minemap::io::detail
