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

namespace py = pybind11;
using Index = LexLS::Index;
using Doubles = py::array_t<double, py::array::c_style | py::array::forcecast>;
using Ints = py::array_t<int64_t, py::array::c_style | py::array::forcecast>;

namespace {

enum Code { OPTIMAL = 0, MAX_ITERATIONS = 1, NUMERICAL_FAILURE = 2, ERROR = 3 };

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
    const Index m = A.shape(0), n = A.shape(1), depth = starts.shape(0) - 1;
    const double* a = A.data();
    const double* lo = lower.data();
    const double* up = upper.data();
    const int64_t* st = starts.data();
    kinds_new_.resize(m);
    for (Index i = 0; i < m; ++i) kinds_new_[i] = kind_of(lo[i], up[i]);
    std::vector<int64_t> st_new(st, st + depth + 1);
    const bool fresh = !built_ || n != n_ || st_new != starts_ || kinds_new_ != kinds_;
    if (fresh) rebuild(n, st_new);
    for (size_t k = 0; k < rows_.size(); ++k) {
      LexLS::dMatrixType& D = data_[k];
      const std::vector<Index>& rows = rows_[k];
      for (Index r = 0; r < (Index)rows.size(); ++r) {
        const Index i = rows[r];
        for (Index j = 0; j < n; ++j) D(r, j) = a[i * n + j];
        D(r, n) = lo[i];
        D(r, n + 1) = up[i];
      }
    }
    return fresh;
  }

  // (x, code, activations, deactivations, factorizations, cycling, message)
  py::tuple solve(bool warm) {
    py::array_t<double> x(n_ < 0 ? 0 : n_);
    double* xp = x.mutable_data();
    int code = OPTIMAL;
    std::string msg;
    if (!built_ || rows_.empty()) {
      for (Index j = 0; j < x.shape(0); ++j) xp[j] = 0.0;
      return py::make_tuple(x, code, 0, 0, 0, 0, msg);
    }
    LexLS::TerminationStatus status = LexLS::TERMINATION_STATUS_UNKNOWN;
    const bool reapply = warm && solved_;
    solved_ = false;
    try {
      if (used_) s_->reset();
      used_ = true;
      for (size_t k = 0; k < rows_.size(); ++k) s_->setData(k, data_[k]);
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
    for (Index j = 0; j < n_; ++j) {
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
  void rebuild(Index n, const std::vector<int64_t>& st) {
    n_ = n;
    starts_ = st;
    kinds_ = kinds_new_;
    rows_.clear();
    for (size_t k = 0; k + 1 < st.size(); ++k) {
      std::vector<Index> rows;
      for (int64_t i = st[k]; i < st[k + 1]; ++i)
        if (kinds_[i] != 0) rows.push_back(i);
      if (!rows.empty()) rows_.push_back(rows);
    }
    const Index nobj = rows_.size();
    data_.assign(nobj, LexLS::dMatrixType());
    ws_.assign(nobj, {});
    std::vector<Index> dims(nobj);
    std::vector<LexLS::ObjectiveType> types(nobj, LexLS::GENERAL_OBJECTIVE);
    for (Index k = 0; k < nobj; ++k) {
      dims[k] = rows_[k].size();
      data_[k].resize(dims[k], n + 2);
    }
    s_.reset();
    solved_ = used_ = false;
    built_ = true;
    if (nobj == 0) return;  // (no LexLSI: x = 0)
    s_.reset(new LexLS::internal::LexLSI(n, nobj, dims.data(), types.data()));
    s_->setParameters(prm_);
  }

  LexLS::ParametersLexLSI prm_;
  Index n_ = -1;
  std::vector<int64_t> starts_;
  std::vector<int8_t> kinds_, kinds_new_;
  std::vector<std::vector<Index>> rows_;  // the rows of hikbench's hierarchy in each LexLS objective
  std::vector<LexLS::dMatrixType> data_;
  std::vector<std::vector<LexLS::ConstraintActivationType>> ws_;  // the last solve's working set
  std::unique_ptr<LexLS::internal::LexLSI> s_;
  bool built_ = false, solved_ = false, used_ = false;
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
