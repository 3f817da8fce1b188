#include "rcal/discrepancy/loo_tuning.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace rcal::discrepancy {
namespace {

// The candidate with the lowest mean cost over the trials other than `skip` (−1: all); −1 when
// every candidate failed on one of them.
int Best(const Eigen::MatrixXd& cost, int skip) {
  int best = -1;
  double best_mean = std::numeric_limits<double>::infinity();
  for (int c = 0; c < cost.rows(); ++c) {
    double sum = 0.0;
    int n = 0;
    for (int t = 0; t < cost.cols(); ++t) {
      if (t == skip) continue;
      sum += cost(c, t);  // NaN propagates: the candidate is out
      ++n;
    }
    const double mean = sum / n;
    if (mean < best_mean) {
      best_mean = mean;
      best = c;
    }
  }
  return best;
}

}  // namespace

LeaveOneOutChoice LeaveOneOutSelect(const Eigen::MatrixXd& cost) {
  if (cost.rows() < 1) throw std::invalid_argument("LeaveOneOutSelect: no candidate");
  if (cost.cols() < 2)
    throw std::invalid_argument("LeaveOneOutSelect: " + std::to_string(cost.cols()) +
                                " trials; leave-one-out needs at least two");
  for (int c = 0; c < cost.rows(); ++c)
    for (int t = 0; t < cost.cols(); ++t)
      if (cost(c, t) < 0.0)
        throw std::invalid_argument("LeaveOneOutSelect: cost(" + std::to_string(c) + ", " +
                                    std::to_string(t) + ") is negative");
  LeaveOneOutChoice out;
  out.in_sample = Best(cost, -1);
  if (out.in_sample < 0)
    throw std::invalid_argument("LeaveOneOutSelect: every candidate failed on some trial");
  out.in_sample_mean = cost.row(out.in_sample).mean();
  for (int t = 0; t < cost.cols(); ++t) {
    const int c = Best(cost, t);
    if (c < 0)
      throw std::invalid_argument("LeaveOneOutSelect: without trial " + std::to_string(t) +
                                  " every candidate failed on some trial");
    out.held_out.push_back(c);
    out.held_out_mean += cost(c, t) / static_cast<double>(cost.cols());
  }
  return out;
}

}  // namespace rcal::discrepancy
