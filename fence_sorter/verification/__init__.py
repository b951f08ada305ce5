"""Numerical verification of a scene: work-precision (accuracy) and the stability campaign.

Each module is a plain library (scenes in, a results object and files out); the CLI modules
``fence_sorter/cli/{accuracy,stability}.py`` only parse arguments and print. The campaigns that
regenerate this repository's reports live beside the package, in ``benchmarks/``.
"""
