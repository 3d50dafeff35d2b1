// hikbench's adapter to SOTH (stack-of-tasks/soth), a Python extension module `_hik_soth`.
//
// A Peer holds one soth::HCOD and its stages' data between calls. load() takes hikbench's
// hierarchy (A (m, n) row-major, lower, upper (m,), starts (depth + 1,)) and writes it into
// the stages' buffers: a row is an equality (lower == upper, SOTH's "twin" bound), one-sided
// or two-sided; free rows and empty levels are left out (they constrain nothing). While n,
// the levels and the kind of every row stay the same, the HCOD object and its active set are
// kept; otherwise a new one is built. solve(warm) runs SOTH's active search, from the last
// call's active set when `warm` (SOTH's own warm start: the active set stays in the HCOD's
// stages), else from the equalities alone. Nothing of SOTH's code is copied here.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <soth/HCOD.hpp>
#include <soth/Stage.hpp>

#include "layout.hpp"

#ifndef NDEBUG
#error "SOTH is timed with its assertions compiled out: build with -DNDEBUG (peers/build.py)"
#endif
#ifdef SOTH_DEBUG
#error "SOTH's debug mode must be compiled out (peers/build.py)"
#endif

namespace py = pybind11;
using namespace hik;  // Doubles, Ints, Row, Layout, the Code values

namespace {

enum Kind : int8_t { FREE = 0, TWIN = 1, LOWER = 2, UPPER = 3, DOUBLE = 4 };

int8_t kind_of(double lo, double up) {
  if (lo == up) return TWIN;
  const bool l = std::isfinite(lo), u = std::isfinite(up);
  return l && u ? DOUBLE : l ? LOWER : u ? UPPER : FREE;
}

class Peer {
 public:
  explicit Peer(double epsilon) : epsilon_(epsilon) {}

  // the hierarchy into the stages' buffers; true when a new HCOD object was built (cold)
  bool load(const Doubles& A, const Doubles& lower, const Doubles& upper, const Ints& starts) {
    const bool fresh = layout_.update(A, lower, upper, starts);
    if (fresh) rebuild();
    const Row n = layout_.n;
    const double* a = A.data();
    const double* lo = lower.data();
    const double* up = upper.data();
    for (size_t k = 0; k < layout_.rows.size(); ++k) {
      Eigen::MatrixXd& J = J_[k];  // column-major: SOTH maps it so
      soth::VectorBound& b = b_[k];
      const std::vector<Row>& rows = layout_.rows[k];
      for (Row r = 0; r < (Row)rows.size(); ++r) {
        const Row i = rows[r];
        for (Row j = 0; j < n; ++j) J(r, j) = a[i * n + j];
        switch (layout_.kinds[i]) {
          case TWIN: b[r] = soth::Bound(lo[i]); break;
          case LOWER: b[r] = soth::Bound(lo[i], soth::Bound::BOUND_INF); break;
          case UPPER: b[r] = soth::Bound(up[i], soth::Bound::BOUND_SUP); break;
          default: b[r] = soth::Bound(lo[i], up[i]); break;
        }
      }
    }
    return fresh;
  }

  // (x, code, activations, deactivations, message)
  py::tuple solve(bool warm) {
    const Row n = layout_.n;
    py::array_t<double> x(n < 0 ? 0 : n);
    double* xp = x.mutable_data();
    int code = OPTIMAL;
    std::string msg;
    activations_ = deactivations_ = 0;
    if (!hcod_) {  // (no row left: x = 0)
      for (Row j = 0; j < x.shape(0); ++j) xp[j] = 0.0;
      return py::make_tuple(x, code, 0, 0, msg);
    }
    soth::Stage::EPSILON = epsilon_;  // (a static of SOTH: set on every call)
    if (!warm || !solved_) hcod_->setInitialActiveSet();
    solved_ = false;
    try {
      hcod_->activeSearch(u_);
      solved_ = true;
    } catch (int thrown) {
      code = MAX_ITERATIONS;
      msg = "soth: active search stopped by SOTH's cap of 1000 iterations (throw " + std::to_string(thrown) + ")";
    } catch (const std::exception& e) {
      code = ERROR;
      msg = std::string("soth: exception: ") + e.what();
    } catch (...) {
      code = ERROR;
      msg = "soth: unknown exception";
    }
    if (code != OPTIMAL) {
      for (Row j = 0; j < n; ++j) xp[j] = std::nan("");
    } else {
      for (Row j = 0; j < n; ++j) {
        xp[j] = u_[j];
        if (!std::isfinite(xp[j])) code = NUMERICAL_FAILURE;
      }
      if (code == NUMERICAL_FAILURE) {
        msg = "soth: x is not finite";
        solved_ = false;
      }
    }
    return py::make_tuple(x, code, activations_, deactivations_, msg);
  }

  void reset() { solved_ = false; }
  double epsilon() const { return epsilon_; }

 private:
  // a new HCOD object, a stage per level of the layout (none when no row is left)
  void rebuild() {
    const auto& levels = layout_.rows;
    hcod_.reset();
    J_.assign(levels.size(), Eigen::MatrixXd());
    b_.assign(levels.size(), soth::VectorBound());
    for (size_t k = 0; k < levels.size(); ++k) {
      J_[k].resize(levels[k].size(), layout_.n);
      b_[k].resize(levels[k].size());
    }
    u_.resize(layout_.n);
    solved_ = false;
    if (levels.empty()) return;
    hcod_.reset(new soth::HCOD(layout_.n, levels.size()));
    for (size_t k = 0; k < levels.size(); ++k) hcod_->pushBackStage(levels[k].size(), J_[k].data(), b_[k].data());
    // SOTH notifies every change of active set: counted as activations / deactivations
    hcod_->notifiorRegistration([this](std::string, soth::ConstraintRef, std::string what) {
      if (what == "update") ++activations_;
      else if (what == "downdate") ++deactivations_;
    });
  }

  double epsilon_;
  Layout<kind_of> layout_;  // the rows of hikbench's hierarchy in each SOTH stage
  std::vector<Eigen::MatrixXd> J_;
  std::vector<soth::VectorBound> b_;
  std::unique_ptr<soth::HCOD> hcod_;
  Eigen::VectorXd u_;
  bool solved_ = false;
  int activations_ = 0, deactivations_ = 0;
};

}  // namespace

PYBIND11_MODULE(_hik_soth, m) {
  m.doc() = "hikbench's adapter to SOTH (built by peers/build.py)";
  m.attr("default_epsilon") = soth::Stage::EPSILON;
  py::class_<Peer>(m, "Peer")
      .def(py::init<double>(), py::arg("epsilon"))
      .def("load", &Peer::load)
      .def("solve", &Peer::solve)
      .def("reset", &Peer::reset)
      .def_property_readonly("epsilon", &Peer::epsilon);
}
