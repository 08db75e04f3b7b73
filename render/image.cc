#include "render/image.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "estimators/error.h"
#include "sim/config.h"

namespace flexbench::render {

Image ToGray(const Image& rgb) {
  if (rgb.channels == 1) return rgb;
  Image gray{rgb.width, rgb.height, 1, {}};
  gray.data.resize(static_cast<size_t>(rgb.width) * rgb.height);
  const cv::Mat src(rgb.height, rgb.width, CV_8UC3, const_cast<std::uint8_t*>(rgb.data.data()));
  cv::Mat dst(gray.height, gray.width, CV_8UC1, gray.data.data());
  cv::cvtColor(src, dst, cv::COLOR_RGB2GRAY);
  return gray;
}

std::string EncodePng(const Image& image) {
  const int type = image.channels == 1 ? CV_8UC1 : CV_8UC3;
  const cv::Mat src(image.height, image.width, type, const_cast<std::uint8_t*>(image.data.data()));
  cv::Mat bgr;
  if (image.channels == 3) {
    cv::cvtColor(src, bgr, cv::COLOR_RGB2BGR);
  } else {
    bgr = src;
  }
  std::vector<std::uint8_t> png;
  bool ok = false;
  try {
    ok = cv::imencode(".png", bgr, png, {cv::IMWRITE_PNG_COMPRESSION, 6});
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) return "";
  return std::string(png.begin(), png.end());
}

Image ReadPng(const std::string& path) {
  cv::Mat m;
  try {
    m = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    m = cv::Mat();
  }
  if (m.empty() || m.depth() != CV_8U || (m.channels() != 1 && m.channels() != 3)) {
    throw InputError(CapForMessage(path) + ": not an 8-bit gray or RGB PNG image");
  }
  Image out{m.cols, m.rows, m.channels(), {}};
  out.data.resize(static_cast<size_t>(m.cols) * m.rows * m.channels());
  cv::Mat dst(m.rows, m.cols, m.channels() == 1 ? CV_8UC1 : CV_8UC3, out.data.data());
  if (m.channels() == 3) {
    cv::cvtColor(m, dst, cv::COLOR_BGR2RGB);
  } else {
    m.copyTo(dst);
  }
  return out;
}

void WritePng(const Image& image, const std::string& path) {
  // Encoded in memory and written here: cv::imwrite lets libpng print "libpng error: Write
  // Error" on stderr when the disk is full (a second line beside ours) and gives no reason.
  const std::string png = EncodePng(image);
  const bool ok = !png.empty();
  if (!ok) throw InputError(path + ": cannot encode PNG");
  errno = 0;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw InputError(path + ": cannot write PNG: " + std::strerror(errno ? errno : EIO));
  errno = 0;
  const size_t written = std::fwrite(png.data(), 1, png.size(), f);
  int err = written == png.size() ? 0 : (errno ? errno : EIO);
  errno = 0;
  if (std::fclose(f) != 0 && err == 0) err = errno ? errno : EIO;
  if (err != 0) {
    std::remove(path.c_str());  // never a truncated image
    throw InputError(path + ": cannot write PNG: " + std::strerror(err));
  }
}

bool IsConstant(const Image& image) {
  if (image.data.empty()) return true;
  const auto [lo, hi] = std::minmax_element(image.data.begin(), image.data.end());
  return *lo == *hi;
}

}  // namespace flexbench::render
