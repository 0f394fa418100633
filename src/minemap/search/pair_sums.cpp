#include "minemap/search/pair_sums.hpp"

#include <cmath>

namespace minemap {

double PairSums::rms_cm() const { return count > 0 ? std::sqrt(sum_squared_distance_cm2 / count) : 0.0; }

PairSums& PairSums::operator+=(const PairSums& other) {
  count += other.count;
  sum_data += other.sum_data;
  sum_model += other.sum_model;
  sum_data_model += other.sum_data_model;
  sum_squared_distance_cm2 += other.sum_squared_distance_cm2;
  weight += other.weight;
  return *this;
}

}  // namespace minemap
