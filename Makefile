# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
# torch first: 2.13.0 is a CPU wheel on this machine's disk; letting stable-baselines3 pick a
# torch itself downloads a multi-GB CUDA build.
TORCH  := torch==2.13.0

.PHONY: demo docs test bench lint clean env-pairs calibrate

$(VENV)/.torch:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --upgrade pip
	$(PIP) install $(TORCH)
	touch $@

# every later install keeps that torch (a constraint, not just "already satisfied")
$(VENV)/constraints.txt: $(VENV)/.torch
	echo "$(TORCH)" > $@

# one stamp per set of extras, redone when pyproject.toml changes; the demo's needs: render
# (pygame-ce) and slam (GTSAM, a pip wheel: the pose graph of its "Maps that bend" stage)
$(VENV)/.deps-base: pyproject.toml $(VENV)/constraints.txt
	$(PIP) install -c $(VENV)/constraints.txt -e ".[render,slam]"
	touch $@

$(VENV)/.deps-test: pyproject.toml $(VENV)/constraints.txt
	$(PIP) install -c $(VENV)/constraints.txt -e ".[dev,docs,render,ray,rllib,torchrl,slam]"
	touch $@

$(VENV)/.deps-bench: pyproject.toml $(VENV)/constraints.txt
	$(PIP) install -c $(VENV)/constraints.txt -e ".[dev,render,bench]"
	touch $@

# The main job on the embedded defaults (a few minutes on 2 cores once .venv exists): the
# paper's example, scripted episodes, a short PPO run with fusion in the loop (on 10 m buildings,
# the ones it is evaluated on) and its evaluation against scripted explorers, map pairs generated
# by the trained policy, the fusion evaluation on them, and maps that bend (a drifting pair merged
# by the pose graph, out/bending.png). `topomerge demo` (agents/commands.py)
# runs those jobs, sends each one's full output to out/logs/NAME.log and prints a short summary:
# where every figure and table went.
DEMO_STEPS ?= 30000
demo: $(VENV)/.deps-base
	$(PY) -m agents.commands demo --out out --steps $(DEMO_STEPS)

# The documentation site (mkdocs.yml, pages in docs/): warnings are errors. tests/test_docs.py
# builds it too, so `make test` (and CI) fails on a broken page.
docs: $(VENV)/.deps-docs
	$(PY) -m mkdocs build --strict

$(VENV)/.deps-docs: pyproject.toml $(VENV)/constraints.txt
	$(PIP) install -c $(VENV)/constraints.txt -e ".[render,docs]"
	touch $@

# the tests, and the documentation site: tests/test_docs.py builds it with warnings as errors
test: $(VENV)/.deps-test
	$(PY) -m pytest -q

# the env-pair benchmark set (tune and test splits) for benchmarks/topo_repeatability.py
env-pairs: $(VENV)/.deps-base
	$(PY) benchmarks/env_pairs.py --out data/env_pairs

# Refit every fitted parameter of the merges (fusion/calibration.json) after changing what they
# read: the topological map extraction, the occupancy grids, the structural search or the grid
# alignment's evidence (CONTRIBUTING.md). Long: it makes the tuning pairs (resumable), then fits
# the search's ranking weights, the structural confidence (it reads the ranking score) on the
# tune, synthetic and generic pairs, the grid confidence on the noise-free pairs and its drift
# terms on top. Review the printed tables and `git diff fusion/calibration.json` before
# committing: a refit moves merge decisions (tests/envs/test_env_hash.py digests).
CALIBRATION ?= out/calibration
calibrate: $(VENV)/.deps-base
	$(PY) benchmarks/env_pairs.py --out data/env_pairs --only tune
	$(PY) benchmarks/env_pairs.py --out data/env_pairs --odometry-noise 0.01 0.02 0.05
	$(PY) -m fusion.calibration fit --model ranking --write
	rm -f $(CALIBRATION)/structural_rows.json
	$(PY) benchmarks/generic_graphs.py --calibration-rows $(CALIBRATION)/structural_rows.json
	$(PY) -m fusion.calibration fit --model structural --cache $(CALIBRATION)/structural_rows.json --write
	$(PY) -m fusion.calibration fit --model grid --write
	$(PY) -m fusion.calibration fit --model grid --drift --extend --write
	$(PY) benchmarks/bending_in_loop.py --settings on --first-seed 0 --worlds 24 --rows $(CALIBRATION)/near_pioneer.jsonl
	$(PY) benchmarks/bending_in_loop.py --settings on --first-seed 0 --worlds 12 --odometry-noise 0.02 --rows $(CALIBRATION)/near_sigma.jsonl
	$(PY) benchmarks/bending_in_loop.py --settings on --first-seed 0 --worlds 8 --robots 4 --rows $(CALIBRATION)/near_team.jsonl
	$(PY) -m fusion.calibration fit --model window_near --rows $(CALIBRATION)/near_pioneer.jsonl $(CALIBRATION)/near_sigma.jsonl $(CALIBRATION)/near_team.jsonl --split dev --write

bench: $(VENV)/.deps-bench
	$(PY) benchmarks/icp_speed.py

lint: $(VENV)/.deps-test
	$(PY) -m ruff check .

clean:
	rm -rf $(VENV) out site .pytest_cache .ruff_cache .hypothesis
	find . -name '*.nbi' -o -name '*.nbc' | xargs rm -f  # numba's kernel caches
