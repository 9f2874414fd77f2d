# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
# torch first: 2.13.0 is a CPU wheel on this machine's disk; letting stable-baselines3 pick a
# torch itself downloads a multi-GB CUDA build.
TORCH  := torch==2.13.0

.PHONY: demo test bench lint clean

$(VENV)/.torch:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --upgrade pip
	$(PIP) install $(TORCH)
	touch $@

# one stamp per set of extras, redone when pyproject.toml changes
$(VENV)/.deps-base: pyproject.toml $(VENV)/.torch
	$(PIP) install -e .
	touch $@

$(VENV)/.deps-test: pyproject.toml $(VENV)/.torch
	$(PIP) install -e ".[dev,render,ray]"
	touch $@

$(VENV)/.deps-bench: pyproject.toml $(VENV)/.torch
	$(PIP) install -e ".[dev,render,bench]"
	touch $@

demo: $(VENV)/.deps-base
	$(PY) benchmarks/paper_example.py --out out

test: $(VENV)/.deps-test
	$(PY) -m pytest -q

bench: $(VENV)/.deps-bench
	$(PY) benchmarks/icp_speed.py

lint: $(VENV)/.deps-test
	$(PY) -m ruff check .

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache .hypothesis
