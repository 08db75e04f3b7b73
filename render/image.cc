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

void WritePng(const Image& image, const std::string& path) {
  const int type = image.channels == 1 ? CV_8UC1 : CV_8UC3;
  const cv::Mat src(image.height, image.width, type, const_cast<std::uint8_t*>(image.data.data()));
  cv::Mat bgr;
  if (image.channels == 3) {
    cv::cvtColor(src, bgr, cv::COLOR_RGB2BGR);
  } else {
    bgr = src;
  }
  // Encoded in memory and written here: cv::imwrite lets libpng print "libpng error: Write
  // Error" on stderr when the disk is full (a second line beside ours) and gives no reason.
  std::vector<std::uint8_t> png;
  bool ok = false;
  try {
    ok = cv::imencode(".png", bgr, png, {cv::IMWRITE_PNG_COMPRESSION, 6});
  } catch (const cv::Exception&) {
    ok = false;
  }
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
