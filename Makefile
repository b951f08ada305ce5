# fence_sorter: the two commands of the README.
#   make run   set up (idempotent) + the node suite on the default scene (impact_flexible) with
#              a short stream (12 parcels of config/streams/default.yaml), recorded to bags/
#   make test  set up (idempotent) + ruff + pytest
SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
ENV := source scripts/env.sh
LINT_PATHS := fence_sorter test scripts

.PHONY: all bootstrap run test lint format check clean

all: run

bootstrap:
	bash scripts/bootstrap.sh

run: bootstrap
	$(ENV) && fence-sorter run --parcels 12 --bag bags/run-$$(date -u +%Y%m%dT%H%M%SZ)

check: bootstrap
	$(ENV) && fence-sorter check

lint: bootstrap
	$(ENV) && ruff check $(LINT_PATHS) && ruff format --check $(LINT_PATHS)

format: bootstrap
	$(ENV) && ruff check --fix $(LINT_PATHS) && ruff format $(LINT_PATHS)

test: bootstrap
	$(ENV) && ruff check $(LINT_PATHS) && ruff format --check $(LINT_PATHS) && pytest -q test/

clean:
	rm -rf .build
