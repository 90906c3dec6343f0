# Entry points of the project. `make demo` and `make test` run `make setup` first (cheap when
# nothing changed: it skips pip and colcon by stamp). Every command runs inside the environment
# through $(IN_ENV), which sources env.sh.
SHELL := /bin/bash
.DEFAULT_GOAL := help

IN_ENV := scripts/in_env.sh
PYTEST_ARGS ?=
ARGS ?=

.PHONY: help setup test lint pytest demo train recipe bench clean distclean

help:
	@echo "make setup      build .venv and ros2_ws (idempotent; skips work by stamp)"
	@echo "make demo       fly the lander (FAST=1 for the short version)"
	@echo "make test       ruff check + ruff format --check + pytest tests/  (PYTEST_ARGS=...)"
	@echo "make train      pd-train \$$(ARGS)"
	@echo "make recipe     the shipped policy's training recipe, one seed (SEED=1; ARGS=--help for more)"
	@echo "make bench      run every bench/*.py"
	@echo "make clean      remove ros2_ws build/install/log and caches (distclean: also .venv)"

setup:
	scripts/setup.sh

lint: setup
	$(IN_ENV) ruff check .
	$(IN_ENV) ruff format --check .

pytest: setup
	$(IN_ENV) pytest $(PYTEST_ARGS)

# pytest exits 5 when it collects no test: that fails `make test` too.
test: setup
	$(IN_ENV) ruff check .
	$(IN_ENV) ruff format --check .
	$(IN_ENV) pytest $(PYTEST_ARGS)

# The main job: the three nodes and a recorder as separate processes over DDS, one landing at the
# real 5 Hz (FAST=1: in lockstep), a bag and a PNG under out/. ros2_run.sh sources env.sh itself.
demo: setup
	scripts/ros2_run.sh pd_bringup pd_demo $(if $(FAST),--fast) $(ARGS)

train: setup
	$(IN_ENV) pd-train $(ARGS)

# The shipped policy's recipe (models/pd_dqn_adapt.md): three pd-train stages from optimal-control
# teachers, runs under runs/ocp__$(SEED); the policy is runs/ocp__$(SEED)/stage3/final.pt (stage 2,
# runs/ocp__$(SEED)/stage2/best.pt, is models/pd_dqn_ocp.pt for seed 1)
recipe: setup
	$(IN_ENV) scripts/train_recipe.sh --adapt --seed $(or $(SEED),1) $(ARGS)

bench: setup
	@shopt -s nullglob; files=(bench/*.py); \
	if [ $${#files[@]} -eq 0 ]; then echo "make bench: no bench/*.py yet"; exit 0; fi; \
	for f in "$${files[@]}"; do \
		echo "=== $$f"; $(IN_ENV) python "$$f" || exit 1; \
	done

clean:
	rm -rf ros2_ws/build ros2_ws/install ros2_ws/log .pytest_cache .ruff_cache
	find . -path ./.venv -prune -o -type d -name __pycache__ -prune -exec rm -rf {} +

distclean: clean
	rm -rf .venv ros2_ws/src
