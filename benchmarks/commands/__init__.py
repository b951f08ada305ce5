"""``python -m benchmarks <campaign>``: one module per campaign, as ``fence_sorter.cli``'s."""
