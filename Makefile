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
	$(ENV) && ruff check $(LINT_PATHS) && ruff format --check $(LINT_PATHS) && pytest -q test/ --durations=40

# every generated report of docs/reports/, each with the arguments its committed version was
# made with and its output named (the package writes nowhere by default but the current
# directory); hours of CPU, niced; versus is left out: it compares with a commit the reader names;
# stability-random exits 1 while an event of its report fails (the report names them); the
# two-host line-scale needs root (network namespaces): run by another user it says so and
# is skipped
reports: bootstrap
	$(ENV) && nice -n 10 fence-sorter accuracy --out docs/reports/accuracy --repeats 3 --max-wall 30 \
		&& nice -n 10 fence-sorter stability --out docs/reports/stability \
		&& nice -n 10 python -m benchmarks paper-sweep all --no-resume --out docs/reports/paper \
		&& nice -n 10 python -m benchmarks paper-sweep fig7-fixed-rz,fig10-fixed-rz,decision-table \
			--no-resume --out docs/reports/paper --table config/decision_table.yaml \
		&& nice -n 10 python -m benchmarks bench --out docs/reports/benchmarks.md \
			--json docs/reports/benchmarks.json \
		&& nice -n 10 python -m benchmarks bench-suite --out docs/reports/benchmarks.md \
			--json docs/reports/bench-suite.json \
		&& nice -n 10 python -m benchmarks bench-suite --rrd --no-write \
			--json docs/reports/bench-suite.json \
		&& nice -n 10 python -m benchmarks faults --out docs/reports/reliability.md \
		&& nice -n 10 python -m benchmarks calibrate-bench --seeds 200 --parcels 8 \
			--fresh-noise 105,106,112,117 --draws 100 --timing-parcels 50 \
			--json docs/reports/calibration.json --doc docs/reports/calibration.md \
		&& nice -n 10 python -m benchmarks line-bench four_units --duration 600 \
			--rates 2000,3000,4000,6000,8000,12000 --out docs/reports/line-bench.md \
		&& nice -n 10 python -m benchmarks line-speed four_units --runs 3 \
			--out docs/reports/line-speed.md --json docs/reports/line-speed.json \
		&& nice -n 10 python -m benchmarks planner-latency --rate-factor 1,2 \
			--out docs/reports/planner.md --json docs/reports/planner.json \
		&& python -m benchmarks limits --parcels 60 --rtf 1 \
			--out docs/reports/limits.md --json docs/reports/limits.json \
		&& { nice -n 10 python -m benchmarks stability-random --events 100000 --seed 1 \
			--workers 2 || [ $$? -eq 1 ]; } \
		&& python -m benchmarks line-scale --units 1,2,4,8 --parcels 8 --seed 3 --rtf 1 \
			--out docs/reports/line-scale.md \
		&& python -m benchmarks line-scale --units 2,4,8 --parcels 8 --seed 3 --hosts 2 \
			--skip-unless-root --out docs/reports/line-scale.md \
		&& nice -n 10 python -m benchmarks.startup --rounds 5 --runs 3 --load 4 \
			--out docs/reports/startup \
		&& nice -n 10 python -m benchmarks.convergence \
		&& nice -n 10 python -m benchmarks.imports \
		&& nice -n 10 python -m benchmarks.dt_max

clean:
	rm -rf .build
