#pragma once
// 8-bit RGB PNG encoding and decoding through libpng, kept behind this header so only one
// translation unit sees png.h (libpng is a private dependency of the minemap library).
// Thread-safety: every function is reentrant; no state is shared between calls. Output bytes are
// a pure function of the pixels (fixed compression settings, no time chunk), so maps written twice
// are byte-identical.
#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

namespace minemap::report {

/// A packed RGB image, rows top to bottom, 3 bytes per pixel, no row padding.
struct RgbImage {
  int width_px = 0;
  int height_px = 0;
  std::vector<std::uint8_t> rgb;  ///< width_px * height_px * 3 bytes

  RgbImage() = default;
  RgbImage(int width, int height, std::uint8_t r, std::uint8_t g, std::uint8_t b);

  std::uint8_t* at(int x_px, int y_px) { return rgb.data() + (static_cast<std::size_t>(y_px) * width_px + x_px) * 3; }
  const std::uint8_t* at(int x_px, int y_px) const {
    return rgb.data() + (static_cast<std::size_t>(y_px) * width_px + x_px) * 3;
  }
};

/// Encodes `image` as a PNG file image in memory. Throws std::invalid_argument when the buffer size
/// does not match the dimensions, std::runtime_error when libpng fails.
std::vector<std::uint8_t> encode_png_rgb8(const RgbImage& image);

/// Encodes and writes atomically (see core/atomic_file.hpp): a failure leaves the old file or
/// none, never a truncated PNG. Throws minemap::OutputError when the file cannot be written.
void write_png_rgb8(const std::filesystem::path& path, const RgbImage& image);

/// Decodes any PNG libpng reads (palette, grey, 16-bit, alpha: converted) to 8-bit RGB. Used by the
/// tests and by tools that check written maps. Throws std::runtime_error naming libpng's message.
RgbImage decode_png_rgb8(std::span<const std::uint8_t> png_bytes);
RgbImage read_png_rgb8(const std::filesystem::path& path);

}  // namespace minemap::report
