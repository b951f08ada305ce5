# fence_sorter: the two commands of the README.
#   make run   set up (idempotent) + environment check + two-node message round trip
#              + one offline sorting event of the default scene (the node suite comes later)
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
	$(ENV) && fence-sorter check && fence-sorter demo-roundtrip \
		&& fence-sorter simulate impact_flexible

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
