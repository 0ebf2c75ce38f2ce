#include "plot.h"

#include "artrace/io/atomic_file.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace artrace::tools {

void plot(const std::string& title, const std::vector<std::pair<std::string, std::vector<double>>>& series,
          const std::filesystem::path& file, const std::string& y_unit, const std::vector<double>& x_values) {
  const int w = 900, h = 460, left = 70, right = 20, top = 40, bottom = 50;
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
  double ymax = 1e-9;
  size_t n = 0;
  for (const auto& s : series) {
    for (double v : s.second) ymax = std::max(ymax, v);
    n = std::max(n, s.second.size());
  }
  ymax *= 1.3;  // headroom for the legend above the curves
  // about eight gridlines, at 1, 2 or 5 times a power of ten
  const double raw = ymax / 8.0, mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double step = raw <= mag ? mag : raw <= 2 * mag ? 2 * mag : raw <= 5 * mag ? 5 * mag : 10 * mag;
  ymax = std::ceil(ymax / step) * step;
  auto X = [&](double i) { return left + static_cast<int>((w - left - right) * i / std::max<double>(1, n - 1)); };
  auto Y = [&](double v) { return h - bottom - static_cast<int>((h - top - bottom) * v / ymax); };
  const cv::Scalar axis(0, 0, 0), grid(225, 225, 225);
  for (double v = 0; v <= ymax + 1e-9; v += step) {
    cv::line(img, {left, Y(v)}, {w - right, Y(v)}, grid);
    char label[32];
    std::snprintf(label, sizeof(label), "%g", v);
    cv::putText(img, label, {8, Y(v) + 5}, cv::FONT_HERSHEY_SIMPLEX, 0.45, axis, 1, cv::LINE_AA);
  }
  for (size_t i = 0; i < n; i += n > 400 ? 100 : n > 100 ? 50 : n > 20 ? 10 : 1) {
    cv::line(img, {X(i), h - bottom}, {X(i), h - bottom + 5}, axis);
    char tick[32];
    std::snprintf(tick, sizeof(tick), "%g", i < x_values.size() ? x_values[i] : static_cast<double>(i));
    cv::putText(img, tick, {X(i) - 10, h - bottom + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.45, axis, 1, cv::LINE_AA);
  }
  cv::line(img, {left, top}, {left, h - bottom}, axis);
  cv::line(img, {left, h - bottom}, {w - right, h - bottom}, axis);
  cv::putText(img, "frame", {w / 2 - 20, h - 12}, cv::FONT_HERSHEY_SIMPLEX, 0.5, axis, 1, cv::LINE_AA);
  cv::putText(img, y_unit, {8, top - 12}, cv::FONT_HERSHEY_SIMPLEX, 0.5, axis, 1, cv::LINE_AA);
  cv::putText(img, title, {left + 10, 24}, cv::FONT_HERSHEY_SIMPLEX, 0.55, axis, 1, cv::LINE_AA);
  const cv::Scalar colours[] = {{200, 90, 20}, {30, 30, 210}, {40, 160, 40}, {150, 40, 150}, {20, 150, 200}};
  for (size_t s = 0; s < series.size(); ++s) {
    const auto& v = series[s].second;
    for (size_t i = 1; i < v.size(); ++i) cv::line(img, {X(i - 1), Y(v[i - 1])}, {X(i), Y(v[i])}, colours[s % 5], 1, cv::LINE_AA);
  }
  // the legend last, on a white box, so that no curve runs through its labels
  const int rows = static_cast<int>(series.size());
  cv::rectangle(img, {w - 268, top}, {w - right - 4, top + 20 * rows + 6}, cv::Scalar(255, 255, 255), cv::FILLED);
  cv::rectangle(img, {w - 268, top}, {w - right - 4, top + 20 * rows + 6}, grid);
  for (size_t s = 0; s < series.size(); ++s) {
    cv::line(img, {w - 260, top + 10 + 20 * static_cast<int>(s)}, {w - 230, top + 10 + 20 * static_cast<int>(s)}, colours[s % 5], 2);
    cv::putText(img, series[s].first, {w - 222, top + 15 + 20 * static_cast<int>(s)}, cv::FONT_HERSHEY_SIMPLEX, 0.45, axis, 1,
                cv::LINE_AA);
  }
  io::write_png(file, img);
}

}  // namespace artrace::tools
