// hikbench's adapter to LexLS (jrl-umi3218/lexls), a Python extension module `_hik_lexls`.
//
// A Peer holds one LexLS::internal::LexLSI and its objectives' data between calls. load()
// takes hikbench's hierarchy (A (m, n) row-major, lower, upper (m,), starts (depth + 1,))
// and writes each level into LexLS's [A, lower, upper] block; free rows and empty levels are
// left out (they constrain nothing); infinite bounds are passed as they are. While n, the levels
// and the kind of every row stay the same, the LexLSI object is kept; otherwise a new one is
// built. solve(warm) re-applies the last solve's working set (the inequalities active at its
// lower or upper bound, LexLS's own warm start) when `warm`, then runs LexLS's active set.
// Nothing of LexLS's code is copied here.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <lexls/lexlsi.h>

#include "layout.hpp"

namespace py = pybind11;
using Index = LexLS::Index;
using namespace hik;  // Doubles, Ints, Row, Layout, the Code values

namespace {

// 0 free, 1 equality, 2 one- or two-sided (LexLS takes both bounds, infinite or not)
int8_t kind_of(double lo, double up) {
  if (lo == up) return 1;
  return std::isfinite(lo) || std::isfinite(up) ? 2 : 0;  // (0: free)
}

class Peer {
 public:
  Peer(double tol_linear_dependence, long max_factorizations) {
    prm_.setDefaults();
    prm_.tol_linear_dependence = tol_linear_dependence;
    prm_.max_number_of_factorizations = max_factorizations;
  }

  // the hierarchy into the objectives' blocks; true when a new LexLSI object was built (cold)
  bool load(const Doubles& A, const Doubles& lower, const Doubles& upper, const Ints& starts) {
    const bool fresh = layout_.update(A, lower, upper, starts);
    if (fresh) rebuild();
    const Row n = layout_.n;
    const double* a = A.data();
    const double* lo = lower.data();
    const double* up = upper.data();
    for (size_t k = 0; k < layout_.rows.size(); ++k) {
      LexLS::dMatrixType& D = data_[k];
      const std::vector<Row>& rows = layout_.rows[k];
      for (Row r = 0; r < (Row)rows.size(); ++r) {
        const Row i = rows[r];
        for (Row j = 0; j < n; ++j) D(r, j) = a[i * n + j];
        D(r, n) = lo[i];
        D(r, n + 1) = up[i];
      }
    }
    return fresh;
  }

  // (x, code, activations, deactivations, factorizations, cycling, message)
  py::tuple solve(bool warm) {
    const Row n = layout_.n;
    py::array_t<double> x(n < 0 ? 0 : n);
    double* xp = x.mutable_data();
    int code = OPTIMAL;
    std::string msg;
    if (!s_) {  // (no row left: x = 0)
      for (Row j = 0; j < x.shape(0); ++j) xp[j] = 0.0;
      return py::make_tuple(x, code, 0, 0, 0, 0, msg);
    }
    LexLS::TerminationStatus status = LexLS::TERMINATION_STATUS_UNKNOWN;
    const bool reapply = warm && solved_;
    solved_ = false;
    try {
      if (used_) s_->reset();
      used_ = true;
      for (size_t k = 0; k < data_.size(); ++k) s_->setData(k, data_[k]);
      if (reapply)
        for (size_t k = 0; k < ws_.size(); ++k)
          for (size_t i = 0; i < ws_[k].size(); ++i)
            if (ws_[k][i] == LexLS::CTR_ACTIVE_LB || ws_[k][i] == LexLS::CTR_ACTIVE_UB)
              s_->api_activate(k, i, ws_[k][i]);
      status = s_->solve();
    } catch (const std::exception& e) {
      code = ERROR;
      msg = std::string("lexls: exception: ") + e.what();
    } catch (...) {
      code = ERROR;
      msg = "lexls: unknown exception";
    }
    const int acts = (int)s_->getActivationsCount(), deacts = (int)s_->getDeactivationsCount();
    const int facts = (int)s_->getFactorizationsCount(), cycling = (int)s_->getCyclingCounter();
    if (code == OPTIMAL && status == LexLS::MAX_NUMBER_OF_FACTORIZATIONS_EXCEEDED) {
      code = MAX_ITERATIONS;
      msg = "lexls: cap of " + std::to_string(prm_.max_number_of_factorizations) +
            " factorizations reached (option max_factorizations)";
    } else if (code == OPTIMAL && status != LexLS::PROBLEM_SOLVED &&
               status != LexLS::PROBLEM_SOLVED_CYCLING_HANDLING) {
      code = NUMERICAL_FAILURE;
      msg = "lexls: termination status " + std::to_string((int)status);
    }
    const LexLS::dVectorType& xs = s_->get_x();
    for (Row j = 0; j < n; ++j) {
      xp[j] = code == ERROR ? std::nan("") : xs[j];
      if (code == OPTIMAL && !std::isfinite(xp[j])) {
        code = NUMERICAL_FAILURE;
        msg = "lexls: x is not finite";
      }
    }
    if (code == OPTIMAL) {
      solved_ = true;
      for (size_t k = 0; k < ws_.size(); ++k) {
        ws_[k].clear();  // (getActiveCtr resizes, it does not clear)
        s_->getActiveCtr(k, ws_[k]);
      }
    }
    return py::make_tuple(x, code, acts, deacts, facts, cycling, msg);
  }

  void reset() { solved_ = false; }
  double tol_linear_dependence() const { return prm_.tol_linear_dependence; }
  long max_factorizations() const { return prm_.max_number_of_factorizations; }

 private:
  // a new LexLSI object for the layout's levels (none when no row is left)
  void rebuild() {
    const Index nobj = layout_.rows.size(), n = layout_.n;
    data_.assign(nobj, LexLS::dMatrixType());
    ws_.assign(nobj, {});
    std::vector<Index> dims(nobj);
    std::vector<LexLS::ObjectiveType> types(nobj, LexLS::GENERAL_OBJECTIVE);
    for (Index k = 0; k < nobj; ++k) {
      dims[k] = layout_.rows[k].size();
      data_[k].resize(dims[k], n + 2);
    }
    s_.reset();
    solved_ = used_ = false;
    if (nobj == 0) return;
    s_.reset(new LexLS::internal::LexLSI(n, nobj, dims.data(), types.data()));
    s_->setParameters(prm_);
  }

  LexLS::ParametersLexLSI prm_;
  Layout<kind_of> layout_;  // the rows of hikbench's hierarchy in each LexLS objective
  std::vector<LexLS::dMatrixType> data_;
  std::vector<std::vector<LexLS::ConstraintActivationType>> ws_;  // the last solve's working set
  std::unique_ptr<LexLS::internal::LexLSI> s_;
  bool solved_ = false, used_ = false;
};

}  // namespace

PYBIND11_MODULE(_hik_lexls, m) {
  m.doc() = "hikbench's adapter to LexLS (built by peers/build.py)";
  LexLS::ParametersLexLSI defaults;
  defaults.setDefaults();
  m.attr("default_tol_linear_dependence") = defaults.tol_linear_dependence;
  m.attr("default_max_factorizations") = (long)defaults.max_number_of_factorizations;
  py::class_<Peer>(m, "Peer")
      .def(py::init<double, long>(), py::arg("tol_linear_dependence"), py::arg("max_factorizations"))
      .def("load", &Peer::load)
      .def("solve", &Peer::solve)
      .def("reset", &Peer::reset)
      .def_property_readonly("tol_linear_dependence", &Peer::tol_linear_dependence)
      .def_property_readonly("max_factorizations", &Peer::max_factorizations);
}
