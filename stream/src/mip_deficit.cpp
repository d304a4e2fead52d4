#include "texstream/stream/mip_deficit.hpp"

#include <algorithm>
#include <cmath>

namespace texstream::stream {

double displayed_level(double wanted, const ResidentLevels& levels) {
  if (!levels.finest) return static_cast<double>(levels.mip_count);
  return std::max(wanted, static_cast<double>(*levels.finest));
}

double weighted_mip_deficit(std::span<const StreamCandidate> list,
                            const std::function<ResidentLevels(TextureId)>& levels) {
  double sum_w = 0, sum = 0;
  for (const StreamCandidate& c : list) {
    const double w = static_cast<double>(c.weight);
    const double wanted = static_cast<double>(c.desired_mip);
    if (!std::isfinite(wanted) || !std::isfinite(w) || w <= 0) continue;
    sum_w += w;
    sum += w * std::max(0.0, displayed_level(wanted, levels(c.texture)) - wanted);
  }
  return sum_w > 0 ? sum / sum_w : 0.0;
}

}  // namespace texstream::stream
