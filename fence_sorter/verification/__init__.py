"""Numerical verification of the twin: work-precision (accuracy), stability campaign, benchmarks.

Each module is a plain library (scenes in, a results object and files out); the CLI modules
``fence_sorter/cli/{accuracy,stability,bench}.py`` only parse arguments and print.
"""
