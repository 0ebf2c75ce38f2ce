// Curves over frames drawn with OpenCV into a PNG: axes, ticks, a legend (benchmark figures).
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace artrace::tools {

/// One curve a series (name, values); the x axis counts samples, labelled with `x_values` when
/// given (one a sample: e.g. the frame each sample was taken at), else the sample index. Written
/// to a temporary name and renamed into place.
void plot(const std::string& title, const std::vector<std::pair<std::string, std::vector<double>>>& series,
          const std::filesystem::path& file, const std::string& y_unit = "ms", const std::vector<double>& x_values = {});

}  // namespace artrace::tools
