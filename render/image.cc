#include "render/image.h"

#include <algorithm>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

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
  bool ok = false;
  try {
    ok = cv::imwrite(path, bgr, {cv::IMWRITE_PNG_COMPRESSION, 6});
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) throw InputError(path + ": cannot write PNG");
}

bool IsConstant(const Image& image) {
  if (image.data.empty()) return true;
  const auto [lo, hi] = std::minmax_element(image.data.begin(), image.data.end());
  return *lo == *hi;
}

}  // namespace flexbench::render
