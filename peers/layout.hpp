// The part both of hikbench's adapters (soth_adapter.cpp, lexls_adapter.cpp) share: the pybind11
// array types, the status codes the Python side reads, and Layout, which says which rows of
// hikbench's hierarchy go into which level of the peer.
//
// hikbench's hierarchy: A (m, n) row-major, lower, upper (m,), starts (depth + 1,) (level k holds
// rows starts[k] .. starts[k + 1] - 1). A free row (kind 0) and an empty level constrain nothing:
// they are left out. Nothing of the peers' code is copied here.
#pragma once

#include <pybind11/numpy.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace hik {

using Doubles = pybind11::array_t<double, pybind11::array::c_style | pybind11::array::forcecast>;
using Ints = pybind11::array_t<int64_t, pybind11::array::c_style | pybind11::array::forcecast>;
using Row = std::ptrdiff_t;

// statuses, mapped to hikbench's by hikbench.solvers.peers
enum Code { OPTIMAL = 0, MAX_ITERATIONS = 1, NUMERICAL_FAILURE = 2, ERROR = 3 };

// The peer's view of a hierarchy: n, the level starts, the kind of every row (KindOf(lower,
// upper): 0 for a free row; each peer tells the kinds it builds differently) and, for each level
// with a row left, hikbench's indices of its rows. While n, the starts and the kinds stay the
// same, the peer keeps its solver object (and its active set: the warm start).
template <int8_t (*KindOf)(double, double)>
struct Layout {
  Row n = -1;
  std::vector<int64_t> starts;
  std::vector<int8_t> kinds;
  std::vector<std::vector<Row>> rows;  // rows[k]: the rows of the peer's k-th level

  // true when the hierarchy's layout differs from the last one (or there was none): the layout
  // is then rebuilt, and the peer must build a new solver object
  bool update(const Doubles& A, const Doubles& lower, const Doubles& upper, const Ints& st) {
    const Row m = A.shape(0), depth = st.shape(0) - 1;
    const double* lo = lower.data();
    const double* up = upper.data();
    kinds_new_.resize(m);
    for (Row i = 0; i < m; ++i) kinds_new_[i] = KindOf(lo[i], up[i]);
    starts_new_.assign(st.data(), st.data() + depth + 1);
    if (n == A.shape(1) && starts_new_ == starts && kinds_new_ == kinds) return false;
    n = A.shape(1);
    starts.swap(starts_new_);
    kinds.swap(kinds_new_);
    rows.clear();
    for (size_t k = 0; k + 1 < starts.size(); ++k) {
      std::vector<Row> level;
      for (int64_t i = starts[k]; i < starts[k + 1]; ++i)
        if (kinds[i] != 0) level.push_back(i);
      if (!level.empty()) rows.push_back(level);
    }
    return true;
  }

 private:
  std::vector<int64_t> starts_new_;
  std::vector<int8_t> kinds_new_;
};

}  // namespace hik
