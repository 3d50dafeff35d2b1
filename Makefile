# The two set-up commands of the README: `make bench` and `make test`.
# Both create .venv if missing and install the package with all it needs.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SUITE  ?= quick
OUT    ?= results/$(SUITE)

.PHONY: install bench test test-all clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

bench: install
	$(VENV)/bin/hikbench run --suite $(SUITE) --out $(OUT)
	$(VENV)/bin/hikbench report $(OUT)

test: install
	$(PY) -m pytest -q -m "not slow"

test-all: install
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
