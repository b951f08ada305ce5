# fence_sorter: the two commands of the README.
#   make run   set up (idempotent) + the node suite on the default scene (impact_flexible) with
#              a short stream (12 parcels of config/streams/default.yaml), recorded to bags/
#              as a rosbag2 bag and a Rerun .rrd
#   make test  set up (idempotent) + ruff + pytest
SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
ENV := source scripts/env.sh
LINT_PATHS := fence_sorter benchmarks test scripts

.PHONY: all bootstrap run test lint format check reports clean

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

# every generated report of docs/, each with the arguments its committed version was made with
# (hours of CPU, niced); versus is left out: it compares with a commit the reader names
reports: bootstrap
	$(ENV) && nice -n 10 fence-sorter accuracy --out docs/reports/accuracy --repeats 3 --max-wall 30 \
		&& nice -n 10 fence-sorter stability \
		&& nice -n 10 fence-sorter optimize --sweep all --no-resume --out docs/reports/paper \
		&& nice -n 10 fence-sorter optimize --sweep fig7-fixed-rz,fig10-fixed-rz,decision-table \
			--no-resume --out docs/reports/paper \
		&& nice -n 10 python -m benchmarks bench \
		&& nice -n 10 python -m benchmarks bench-suite \
		&& nice -n 10 python -m benchmarks faults \
		&& nice -n 10 python -m benchmarks calibrate-bench --seeds 200 --parcels 8 \
			--fresh-noise 105,106,112,117 --draws 100 --timing-parcels 50 \
			--json docs/reports/calibration.json --doc docs/reports/calibration.md \
		&& nice -n 10 python -m benchmarks.startup --rounds 5 --runs 3 --load 4

clean:
	rm -rf .build
