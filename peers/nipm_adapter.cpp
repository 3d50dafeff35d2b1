// hikbench's adapter to NIPM-HLSP (pfeiffer-kai/NIPM-HLSP), a Python extension module `_hik_nipm`.
//
// NIPM-HLSP takes, for each priority level l, equality rows Ae x = be and inequality rows
// Ai x >= bi (nipm_hlsp.h; the sign as its solver treats it, tested in tests/solvers/test_peers.py).
// load() takes hikbench's hierarchy (A (m, n) row-major, lower, upper (m,), starts (depth + 1,))
// and writes each level into these four blocks: an equality row (lower == upper) into Ae, be =
// lower; a finite lower bound as the row a x >= lower and a finite upper bound as -a x >= -upper
// into Ai, bi (a two-sided row gives both, lower first); free rows and empty levels are left out
// (they constrain nothing). While n,
// the levels and the kind of every row stay the same, the blocks keep their shapes.
//
// NIPM-HLSP has no warm start, and one solver object solves once (its solve() consumes the
// active set it builds level by level): solve() builds a fresh nipmhlsp::NIpmHLSP, passes it
// the blocks and runs its interior point method. Its options are constants of its `options`
// struct; peers/build.py makes four of them read hik_nipm::settings(), set here before each
// solve. NIPM-HLSP reports no status: solve() returns true; what it exposes is its number of
// Newton iterations (`iter`, summed over levels; a level stopping at its cap counts cap + 1)
// and `KKT`, the sum over levels of the norm of the KKT residual its Newton loop ended on (a
// level converges when that norm is below KKT_thres). Nothing of NIPM-HLSP's code is copied here.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstdio>
#include <cstdint>
#include <string>
#include <vector>

#include <nipm_hlsp/nipm_hlsp.h>

#include "layout.hpp"

namespace py = pybind11;
using namespace hik;  // Doubles, Ints, Row, Layout, the Code values

namespace hik_nipm {
// the options NIPM-HLSP's patched options.h reads (declared there by peers/build.py, with its defaults)
Settings& settings() {
  static Settings s;
  return s;
}
}  // namespace hik_nipm

namespace {

enum Kind : int8_t { FREE = 0, EQUALITY = 1, LOWER = 2, UPPER = 3, BOTH = 4 };

std::string g3(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

int8_t kind_of(double lo, double up) {
  if (lo == up) return EQUALITY;
  const bool l = std::isfinite(lo), u = std::isfinite(up);
  return l && u ? BOTH : l ? LOWER : u ? UPPER : FREE;
}

class Peer {
 public:
  Peer(int max_iterations, double kkt_tolerance, double linear_dependence, double activation_threshold) {
    opt_.maxIter = max_iterations;
    opt_.KKT_thres = kkt_tolerance;
    opt_.linearDependency = linear_dependence;
    opt_.activationThres = activation_threshold;
  }

  // the hierarchy into each level's Ae, be, Ai, bi; true when the blocks were re-shaped
  bool load(const Doubles& A, const Doubles& lower, const Doubles& upper, const Ints& starts) {
    const bool fresh = layout_.update(A, lower, upper, starts);
    if (fresh) rebuild();
    const Row n = layout_.n;
    const double* a = A.data();
    const double* lo = lower.data();
    const double* up = upper.data();
    for (size_t k = 0; k < layout_.rows.size(); ++k) {
      Row e = 0, i = 0;
      for (const Row r : layout_.rows[k]) {
        const int8_t kind = layout_.kinds[r];
        const Eigen::Map<const Eigen::RowVectorXd> row(a + r * n, n);
        if (kind == EQUALITY) {
          Ae_[k].row(e) = row;
          be_[k][e++] = lo[r];
          continue;
        }
        if (kind == LOWER || kind == BOTH) {
          Ai_[k].row(i) = row;
          bi_[k][i++] = lo[r];
        }
        if (kind == UPPER || kind == BOTH) {
          Ai_[k].row(i) = -row;
          bi_[k][i++] = -up[r];
        }
      }
    }
    return fresh;
  }

  // (x, code, newton_iterations, kkt_residual, message)
  py::tuple solve() {
    const Row n = layout_.n;
    py::array_t<double> x(n < 0 ? 0 : n);
    double* xp = x.mutable_data();
    const size_t p = layout_.rows.size();
    if (p == 0 || n == 0) {  // (no row left, or no variable: x = 0)
      for (Row j = 0; j < x.shape(0); ++j) xp[j] = 0.0;
      return py::make_tuple(x, (int)OPTIMAL, 0, 0.0, std::string());
    }
    hik_nipm::settings() = opt_;  // (read by NIPM-HLSP's objects as they are built, below)
    int code = OPTIMAL;
    std::string msg;
    double iterations = 0, kkt = NAN;
    try {
      nipmhlsp::NIpmHLSP s((int)p, (int)n);
      for (size_t k = 0; k < p; ++k) s.setData((int)k, Ae_[k], be_[k], Ai_[k], bi_[k]);
      s.solve();
      iterations = s.iter;
      kkt = s.KKT;
      const Eigen::VectorXd xs = s.get_x();
      for (Row j = 0; j < n; ++j) xp[j] = xs[j];
    } catch (const std::exception& e) {
      code = ERROR;
      msg = std::string("nipm-hlsp: exception: ") + e.what();
    } catch (...) {
      code = ERROR;
      msg = "nipm-hlsp: unknown exception";
    }
    if (code == OPTIMAL) {
      for (Row j = 0; j < n; ++j)
        if (!std::isfinite(xp[j])) {
          code = NUMERICAL_FAILURE;
          msg = "nipm-hlsp: x is not finite";
          break;
        }
    }
    if (code == OPTIMAL && !std::isfinite(kkt)) {
      code = NUMERICAL_FAILURE;
      msg = "nipm-hlsp: its KKT residual is not finite";
    } else if (code == OPTIMAL && kkt >= (double)p * opt_.KKT_thres) {
      // (a level converges when its residual is below KKT_thres, else it stops at its cap: a sum
      // of p residuals at or above p * KKT_thres has one at or above KKT_thres)
      code = MAX_ITERATIONS;
      msg = "nipm-hlsp: a level stopped at the cap of " + std::to_string(opt_.maxIter) +
            " Newton iterations (option max_iterations): KKT residual " + g3(kkt) +
            " summed over " + std::to_string(p) + " levels, not below levels x kkt_tolerance";
    }
    if (code == ERROR) {
      for (Row j = 0; j < n; ++j) xp[j] = std::nan("");
    }
    return py::make_tuple(x, code, (long)iterations, kkt, msg);
  }

  int levels() const { return (int)layout_.rows.size(); }
  int max_iterations() const { return opt_.maxIter; }
  double kkt_tolerance() const { return opt_.KKT_thres; }
  double linear_dependence() const { return opt_.linearDependency; }
  double activation_threshold() const { return opt_.activationThres; }

 private:
  // each level's blocks shaped by the kinds of its rows
  void rebuild() {
    const size_t p = layout_.rows.size();
    const Row n = layout_.n;
    Ae_.assign(p, Eigen::MatrixXd());
    Ai_.assign(p, Eigen::MatrixXd());
    be_.assign(p, Eigen::VectorXd());
    bi_.assign(p, Eigen::VectorXd());
    for (size_t k = 0; k < p; ++k) {
      Row me = 0, mi = 0;
      for (const Row r : layout_.rows[k]) {
        const int8_t kind = layout_.kinds[r];
        me += kind == EQUALITY;
        mi += kind == BOTH ? 2 : kind == EQUALITY ? 0 : 1;
      }
      Ae_[k].resize(me, n);
      be_[k].resize(me);
      Ai_[k].resize(mi, n);
      bi_[k].resize(mi);
    }
  }

  hik_nipm::Settings opt_;
  Layout<kind_of> layout_;  // the rows of hikbench's hierarchy in each NIPM-HLSP level
  std::vector<Eigen::MatrixXd> Ae_, Ai_;
  std::vector<Eigen::VectorXd> be_, bi_;
};

}  // namespace

PYBIND11_MODULE(_hik_nipm, m) {
  m.doc() = "hikbench's adapter to NIPM-HLSP (built by peers/build.py)";
  const hik_nipm::Settings defaults;
  m.attr("default_max_iterations") = defaults.maxIter;
  m.attr("default_kkt_tolerance") = defaults.KKT_thres;
  m.attr("default_linear_dependence") = defaults.linearDependency;
  m.attr("default_activation_threshold") = defaults.activationThres;
  py::class_<Peer>(m, "Peer")
      .def(py::init<int, double, double, double>(), py::arg("max_iterations"), py::arg("kkt_tolerance"),
           py::arg("linear_dependence"), py::arg("activation_threshold"))
      .def("load", &Peer::load)
      .def("solve", &Peer::solve)
      .def_property_readonly("levels", &Peer::levels)
      .def_property_readonly("max_iterations", &Peer::max_iterations)
      .def_property_readonly("kkt_tolerance", &Peer::kkt_tolerance)
      .def_property_readonly("linear_dependence", &Peer::linear_dependence)
      .def_property_readonly("activation_threshold", &Peer::activation_threshold);
}
