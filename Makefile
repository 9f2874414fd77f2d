# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
# torch first: 2.13.0 is a CPU wheel on this machine's disk; letting stable-baselines3 pick
# a torch itself downloads a multi-GB CUDA build.
TORCH  := torch==2.13.0

.PHONY: demo test bench lint clean

$(VENV)/.torch:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --upgrade pip
	$(PIP) install $(TORCH)
	touch $@

$(VENV)/.installed-%: pyproject.toml $(VENV)/.torch
	$(PIP) install -e ".[$*]"
	touch $@

demo: $(VENV)/.installed-bench
	$(PY) benchmarks/paper_example.py

test: $(VENV)/.installed-dev,render
	$(PY) -m pytest -q

bench: $(VENV)/.installed-dev,bench
	$(PY) benchmarks/icp_speed.py

lint: $(VENV)/.installed-dev
	$(PY) -m ruff check .

clean:
	rm -rf $(VENV) out .pytest_cache
