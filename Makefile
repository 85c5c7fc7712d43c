# physgnn — `make help` lists the targets.
.DEFAULT_GOAL := help
# Every path below is relative to the checkout: `make -f <checkout>/Makefile` from elsewhere is
# refused in one line (make -C <checkout> works).
ROOT := $(patsubst %/,%,$(dir $(abspath $(lastword $(MAKEFILE_LIST)))))
ifneq ($(ROOT),$(CURDIR))
$(error run make in the checkout: make -C $(ROOT) <target>, or cd $(ROOT))
endif
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
TORCH_PIN ?= torch==2.13.0
PRESET ?= small
ARGS ?=
SHARDS ?= 2
LAUNCHER ?= local
EXPERIMENT ?= ablation_M
# OpenMP threads spin briefly, then sleep: the default 300 000 spins made 2-thread steps about
# 8x slower when other processes kept the cores busy (physgnn/__init__.py, docs/PERFORMANCE.md).
export GOMP_SPINCOUNT ?= 1000

help: ## List the targets
	@grep -hE '^[a-zA-Z_-]+:.*?## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*?## "}; {printf "  \033[36m%-12s\033[0m %s\n", $$1, $$2}'

install: ## Make .venv and install physgnn with its dev tools, the Hydra launchers and the docs tools (torch 2.13: pip's wheel for this machine; nothing compiled)
	test -x $(PY) || python3 -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q "$(TORCH_PIN)"
	$(PIP) install -q -e ".[dev,launchers,docs]"
	$(PY) -c "import torch, torch_geometric, lightning, pybullet, h5py, submitit, hydra_plugins.hydra_joblib_launcher; print('physgnn environment ready: torch', torch.__version__)"

test: ## Run the fast test suite, one worker per core, a test file per worker (and list its 15 slowest tests)
	$(PY) -m pytest -n auto --dist loadfile --durations=15 $(ARGS)

test-slow: ## Run only the slow tests
	$(PY) -m pytest -m slow $(ARGS)

lint: ## Lint and check formatting with ruff
	$(VENV)/bin/ruff check physgnn tests examples
	$(VENV)/bin/ruff format --check physgnn tests examples

format: ## Format and autofix with ruff
	$(VENV)/bin/ruff format physgnn tests examples
	$(VENV)/bin/ruff check --fix physgnn tests examples

data: ## Generate the dataset (PRESET=small|tiny|paper) under outputs/data/<preset>
	$(PY) -m physgnn.generate data=$(PRESET) $(ARGS)

data-shards: ## Generate the dataset in SHARDS shards, one job each of a Hydra launcher, merged at the end (PRESET= SHARDS=2 LAUNCHER=local|slurm_cpu; docs/DATA.md)
	$(PY) -m physgnn.generate -m data=$(PRESET) num_shards=$(SHARDS) 'shard=range(0,$(SHARDS))' hydra/launcher=$(LAUNCHER) $(ARGS)

data-report: ## Print Table 1 of the dataset (PRESET=small; PHYSGNN_OUTPUTS moves outputs/)
	$(PY) -m physgnn.data_report preset=$(PRESET) $(ARGS)

train: ## Train the baseline on data=small (ARGS: Hydra overrides, e.g. ARGS="model.network.M=3 seed=1")
	$(PY) -m physgnn.train $(ARGS)

sweep: ## Run a whole ablation sweep (EXPERIMENT=ablation_H|ablation_M|ablation_connectivity|ablation_lambda|ablation_components|ablation_contacts)
	$(PY) -m physgnn.train +experiment=$(EXPERIMENT) $(ARGS)

study: ## The ablation study: every unique sweep configuration x 3 seeds, results in docs/results/ (ARGS: --dry-run, launcher.n_jobs=N, budget.steps=N)
	$(PY) -m physgnn.study $(ARGS)

eval: ## Evaluate every finished run under outputs/ and write outputs/report/ (ARGS: runs=PATH ...)
	$(PY) -m physgnn.eval $(ARGS)

ship: ## Export a run's best weights as the shipped model run=pretrained loads (RUN=<run folder> [OUT=<folder>] [CHECKPOINT=<file>])
	@test -n "$(RUN)" || { echo "error: make ship needs RUN=<a finished run folder> (e.g. make ship RUN=outputs/runs/baseline/<time>)" >&2; exit 2; }
	$(PY) -m physgnn.ship $(RUN) $(or $(OUT),physgnn/pretrained) $(CHECKPOINT)

default-table: ## The default model's table per seed from the study's registry, with each figure's commit (docs/results/default.md; REGISTRY= OUT= KEY= STEPS=)
	$(PY) -m physgnn.ablation.default_table $(or $(REGISTRY),docs/results/registry.jsonl) $(or $(OUT),docs/results/default.md) $(or $(KEY),baseline) $(STEPS)

fingerprint: ## Re-pin the numerics fingerprint (tests/fingerprint.json) after a deliberate change of training numerics
	PHYSGNN_REPIN=1 OMP_NUM_THREADS=1 $(PY) -m pytest tests/test_fingerprint.py -p no:cacheprovider

learning-curve: ## Learning curve of a run's checkpoints evaluated together (REPORT=<eval report folder> [OUT=<folder>])
	$(PY) -m physgnn.report.learning_curve $(REPORT) $(OUT)

bench: ## Accuracy versus time: outputs/bench/bench.{json,md} (ARGS: e.g. quick=true threads=1)
	$(PY) -m physgnn.bench $(ARGS)

sleep-study: ## Sleeping spheres off vs on, OOD (c) and a resting pile (RUN=a run folder)
	$(PY) -m physgnn.sleep_study run=$(RUN) $(ARGS)

docs: ## Build the documentation site into site/ (mkdocs build --strict: a broken link or a warning fails; needs the docs extra)
	$(VENV)/bin/mkdocs build --strict

torch-floor: ## The fast tests on the oldest torch pyproject.toml allows, in a throwaway venv under /tmp (TORCH=<version> for another; ARGS: pytest's)
	TORCH=$(TORCH) scripts/check_torch_floor.sh $(ARGS)

clean: ## Remove caches (keeps outputs/)
	rm -rf .pytest_cache .ruff_cache .hypothesis site
	find . -name __pycache__ -type d -prune -exec rm -rf {} +

.PHONY: help install test test-slow lint format data data-shards data-report train sweep study eval bench sleep-study clean ship default-table fingerprint learning-curve docs torch-floor
