# The two set-up commands of the README: `make bench` and `make test`.
# Both create .venv if missing, install the package with all it needs (extras all, test), and
# compile hcod's numba kernels once (`hikbench warmup`: 1-4 min on a new machine, ~1 s after).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SUITE  ?= quick
OUT    ?= results/$(SUITE)

# the C++ peers SOTH, LexLS and NIPM-HLSP (docs/peers.md): sources from PEERS_SRC (a folder holding their pinned
# tarballs; default ../shared/third_party when it exists, else a shallow clone at the pinned commits);
# MARCH_NATIVE=1 adds -march=native (recorded in run.json); PEERS_JOBS=N compiler processes (default: the cores)
PEERS_SRC    ?= $(if $(wildcard ../shared/third_party),../shared/third_party,)
MARCH_NATIVE ?= 0
PEERS_JOBS   ?=
PEERS_STAMP  := $(VENV)/.peers-installed

.PHONY: install warmup bench paper peers test test-all clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[all,test]'
	touch $(STAMP)

install: $(STAMP)

$(PEERS_STAMP): pyproject.toml | $(STAMP)
	$(PY) -m pip install --quiet -e '.[peers]'
	touch $(PEERS_STAMP)

peers: $(PEERS_STAMP)
	$(PY) peers/build.py $(if $(PEERS_SRC),--src $(PEERS_SRC)) $(if $(filter 1,$(MARCH_NATIVE)),--march-native) \
		$(if $(PEERS_JOBS),--jobs $(PEERS_JOBS))

warmup: install
	$(VENV)/bin/hikbench warmup

bench: warmup
	$(VENV)/bin/hikbench run --suite $(SUITE) --out $(OUT)
	$(VENV)/bin/hikbench report $(OUT)

# the ICRA 2010 claims: paper suite (~5 min) + reach scenario, report, PASS/FAIL table
paper: warmup
	$(VENV)/bin/hikbench run --suite paper --out results/paper
	$(VENV)/bin/hikbench scenario reach --solver hcod --solver cascade-daqp --solver pink --warm-start none stage time \
		--out results/paper/scenarios/reach --plot
	$(VENV)/bin/hikbench report results/paper
	$(VENV)/bin/hikbench claims results/paper

test: warmup
	$(PY) -m pytest -q -m "not slow"

test-all: warmup
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
