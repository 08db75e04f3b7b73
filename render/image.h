// A plain 8-bit image, row-major, top row first (the orientation of a photo, not of OpenGL).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace flexbench::render {

struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;  // 1 (gray) or 3 (RGB)
  std::vector<std::uint8_t> data;

  std::uint8_t* Row(int r) { return data.data() + static_cast<size_t>(r) * width * channels; }
  const std::uint8_t* Row(int r) const {
    return data.data() + static_cast<size_t>(r) * width * channels;
  }
};

// ITU-R BT.601 luma, the weights OpenCV's RGB2GRAY uses.
Image ToGray(const Image& rgb);

// Writes a PNG (fixed compression level, so the same image gives the same bytes). Throws
// flexbench::InputError naming the path when it cannot be written.
void WritePng(const Image& image, const std::string& path);

// The PNG file's bytes (WritePng's encoding) in memory; empty when it cannot be encoded.
std::string EncodePng(const Image& image);

// An 8-bit gray or RGB PNG (RGB order). Throws flexbench::InputError naming the path otherwise.
Image ReadPng(const std::string& path);

// True when all pixels are equal: a frame that rendered nothing (a known silent failure of
// offscreen GL set-ups).
bool IsConstant(const Image& image);

}  // namespace flexbench::render
