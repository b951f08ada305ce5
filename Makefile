# fence_sorter: the two commands of the README.
#   make run   set up (idempotent) + the node suite on the default scene (impact_flexible) with
#              a short stream (12 parcels of config/streams/default.yaml), recorded to bags/
#              as a rosbag2 bag and a Rerun .rrd
#   make test  set up (idempotent) + ruff + pytest
SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
ENV := source scripts/env.sh
LINT_PATHS := fence_sorter benchmarks test scripts

.PHONY: all bootstrap run test lint format check clean

all: run

bootstrap:
	bash scripts/bootstrap.sh

run: bootstrap
	$(ENV) && stamp=$$(date -u +%Y%m%dT%H%M%SZ) \
		&& fence-sorter run --parcels 12 --bag bags/run-$$stamp --rrd bags/run-$$stamp.rrd

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
